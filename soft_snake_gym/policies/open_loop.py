"""Open-loop serpenoid (docs/model.md §7): the rest curvature follows the traveling wave."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from soft_snake_gym.gaits import SerpenoidParams, serpenoid, serpenoid_on_nodes, serpenoid_phase
from soft_snake_gym.policies.base import BaselinePolicy

__all__ = ["OpenLoopParams", "OpenLoopSerpenoid", "SerpenoidParams"]


class _SerpenoidPolicy(BaselinePolicy):
    """Shared by the bending controllers: a clock in ``state[:, 0]``, the turning bias.

    The bias ``gamma`` of the gait (docs/model.md §6) comes from :meth:`turning_bias`: the gait's
    constant ``gamma`` here, a heading controller's output in
    :class:`~soft_snake_gym.policies.los.LOSGuidance`.
    """

    Params = SerpenoidParams
    needs = ("kappa", "kappa_dot")
    controls = "curvature"
    suggestion = "use 'inching' or 'inching-pid' on SoftWorm-v0"

    def _setup(self) -> None:
        layout = self.layout
        self.n_outputs = layout.n_nodes - 2
        p = self.params
        alpha, self.delta, gamma = serpenoid_on_nodes(
            p.alpha, p.delta, layout.n_nodes, layout.design_nodes, p.gamma
        )
        #: the parameters as each node runs them (alpha, delta, gamma mapped onto arc length).
        self.gait = dataclasses.replace(p, alpha=alpha, delta=self.delta, gamma=gamma)
        #: per-node angle of a design node's 1 rad (``l / l_d``; 1.0 on an unrefined rod).
        self.edge_ratio = serpenoid_on_nodes(1.0, 1.0, layout.n_nodes, layout.design_nodes)[0]
        self.state_size = 1 + self.n_outputs

    def clock_phase(self, t: np.ndarray) -> np.ndarray:
        """Centralized phases ``omega t + delta j + psi0``, (n_envs, N-2) [rad]."""
        p = self.gait
        return serpenoid_phase(0.0, self.n_outputs, 0.0, self.delta, p.psi0)[None, :] + (p.omega * t[:, None])

    def turning_bias(self, obs: np.ndarray, state: np.ndarray) -> float | np.ndarray:
        """The bias ``gamma`` per node [rad]: a float, or (n_envs, 1) per env; the gait's here."""
        return self.gait.gamma

    def desired(
        self, psi: np.ndarray, gamma: float | np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(kappa_des, kappa_dot_des)`` at phases psi advancing at omega.

        With the bias ``gamma`` per node [rad] (a float or (n_envs, 1)); None: the gait's. A bias
        that changes in time adds ``gamma_dot sec^2(phi_des / 2)`` to the true rate, which is
        left out: the closed loops correct it.
        """
        p = self.gait
        return serpenoid(psi, p.omega, p.alpha, p.gamma if gamma is None else gamma)


@dataclass(frozen=True)
class OpenLoopParams(SerpenoidParams):
    """Serpenoid gait plus the gain that keeps the rest curvature on the gait.

    Attributes:
        rest_gain: ``r`` [1/s] in ``u = kappa_dot_des + r (kappa_des - kbar)`` (10; 0 gives the
            bare law ``u = kappa_dot_des``).
    """

    rest_gain: float = 10.0

    def __post_init__(self) -> None:
        """Check the gait's values and ``rest_gain >= 0``."""
        super().__post_init__()
        if not self.rest_gain >= 0:
            raise ValueError(f"rest_gain = {self.rest_gain!r} 1/s must be >= 0")


class OpenLoopSerpenoid(_SerpenoidPolicy):
    """The rest curvature follows the serpenoid (docs/model.md §7).

    ``u = kappa_dot_des + rest_gain (kappa_des - kbar)``.

    ``kbar`` is the controller's own command (the integral of its rates, what a motor's
    position would be), not a measurement of the body, so this is open loop with respect to
    the body. The correction matters only when the episode does not start at the gait's rest
    shape: from the env's default straight start, the bare law ``u = kappa_dot_des`` would
    carry the constant offset ``-kappa_des(0)`` in ``kbar`` for ever (measured: 0.048 m/s
    instead of 0.115 m/s at the thesis gait). Started on the gait (``initial_shape=
    "serpenoid"``), the correction is zero and ``u = kappa_dot_des`` exactly.

    Args:
        env: SoftEel env (or a DummyVecEnv of them).
        alpha, omega, delta, gamma, psi0, rest_gain: see :class:`OpenLoopParams`.
    """

    name = "open-loop"
    Params = OpenLoopParams
    needs = ("kappa", "kappa_dot", "kbar")

    def _control(self, obs, state):
        t = state[:, 0].copy()
        kappa_des, kappa_dot_des = self.desired(self.clock_phase(t), self.turning_bias(obs, state))
        state[:, 0] = t + self.layout.dt
        u = kappa_dot_des + self.params.rest_gain * (kappa_des - self.block(obs, "kbar"))
        return u, np.abs(kappa_des - self.block(obs, "kappa"))
