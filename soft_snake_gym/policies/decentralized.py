"""Decentralized phase PID (docs/model.md §7): no shared clock, each node sees its head-ward neighbour.

Node j estimates its own phase from its turning angle and rate,
``psihat_j = atan2(phi_j - gamma, phi_dot_j / omega)`` (gamma: the turning bias, 0 by default), and takes its reference phase from the
neighbour toward the head, ``psi_j = psihat_(j+1) - delta``. The head-most interior node
closes the chain either *circulant* (``psi_(N-2) = psihat_1 - delta``, exact when
``delta (N-2)`` is a multiple of 2 pi) or *pacemaker* (it runs the clock). The same PID law
as :class:`~soft_snake_gym.policies.pid.CurvaturePID` then acts on that phase.

For its first ``startup`` seconds (2 by default) every node runs the centralized clock instead, so
that the chain starts from the gait whatever the body's start. From a straight, still body
(the env's default start) there is no phase to estimate: ``psihat`` is then the phase of the
start's small vibrations, and the chain amplifies any difference in them, the integration
step's included. Measured with ``startup=0`` over seeds 0-23 of ``SoftEel-v0`` at h, h/4 and
h/16: the circulant chain never starts a wave from 4 of them (all nodes bent one way, the
integral cancelling the feed-forward: under 0.001 m/s), and its curvature error differs between
the steps by up to 3.7x from the others. With the start-up every seed swims (0.1247 to 0.1248
m/s at every step) and every error agrees within 2.1 % (0.0096 to 0.0098); the pacemaker closure, whose
errors differed by up to 16 % without it, within 2.1 % too.

Default gains are (Kp, Kd, Ki) = (10, 2, 1), the sources' second set, not (10, 1, 5): with
(10, 1, 5) the chain of neighbour-to-neighbour phase references is string-unstable in this
model. Measured from rest at the thesis gait, mean curvature error over 2-6 s with the
integration step divided by 16 (converged): centralized 0.0063, pacemaker 0.037, circulant
0.056 with (10, 1, 5); 0.0054, 0.0061, 0.0075 with (10, 2, 1). At the default step backward
Euler's numerical damping hid the instability (0.0055, 0.0054, 0.0145 with (10, 1, 5));
SDIRK2, the default in water since, shows it there too (circulant 0.063).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from soft_snake_gym.policies.open_loop import _SerpenoidPolicy
from soft_snake_gym.policies.pid import PIDParams, pid_law

__all__ = ["DecentralizedPhasePID", "DecentralizedParams", "estimate_phase"]


@dataclass(frozen=True)
class DecentralizedParams(PIDParams):
    """PID parameters plus the closure of the neighbour chain and the start-up.

    Attributes:
        closure: "circulant" or "pacemaker".
        startup: seconds from the episode's start during which every node runs the clock
            (the centralized PID) before it takes its phase from its neighbour (2; 0: the chain
            from the first step, the sources' controller from their start on the gait).
    """

    Kd: float = 2.0
    Ki: float = 1.0
    closure: Literal["circulant", "pacemaker"] = "circulant"
    startup: float = 2.0

    def __post_init__(self) -> None:
        """Check the PID values, ``closure`` and ``startup``."""
        super().__post_init__()
        if self.closure not in ("circulant", "pacemaker"):
            raise ValueError(f"closure = {self.closure!r} must be 'circulant' or 'pacemaker'")
        if not (math.isfinite(self.startup) and self.startup >= 0):
            raise ValueError(
                f"startup = {self.startup!r} s must be finite and >= 0 (0: no start-up on the clock)"
            )


def estimate_phase(
    kappa: np.ndarray, kappa_dot: np.ndarray, omega: float, gamma: float | np.ndarray = 0.0
) -> np.ndarray:
    """``psihat = atan2(phi - gamma, phi_dot / omega)`` with ``phi = 2 atan(kappa / 2)`` (docs/model.md §7).

    The turning bias ``gamma`` [rad] (per node: a float or (n_envs, 1)) is taken off the turning
    angle first: the gait's ``phi = alpha sin(psi) + gamma`` oscillates about it.
    """
    phi = 2.0 * np.arctan(0.5 * kappa)
    phi_dot = 4.0 * kappa_dot / (kappa * kappa + 4.0)
    return np.arctan2(phi - gamma, phi_dot / omega)


class DecentralizedPhasePID(_SerpenoidPolicy):
    """PID on each node's phase taken from its head-ward neighbour (docs/model.md §7).

    State per env: ``[t, integral_1 .. integral_(N-2)]`` (t only drives the pacemaker).

    Args:
        env: SoftEel env (or a DummyVecEnv of them).
        closure: "circulant" (default) or "pacemaker".
        startup: seconds on the clock before the chain takes over (2).
        alpha, omega, delta, gamma, psi0, Kp, Kd, Ki, saturation: see :class:`PIDParams`.
    """

    name = "decentralized"
    Params = DecentralizedParams

    def start_up(self, psi: np.ndarray, t: np.ndarray) -> np.ndarray:
        """The reference phases: ``psi``, or the clock's for envs still in their start-up (``t < startup``)."""
        starting = t < self.params.startup
        return np.where(starting[:, None], self.clock_phase(t), psi) if starting.any() else psi

    def _control(self, obs, state):
        p = self.params
        t = state[:, 0].copy()
        kappa = self.block(obs, "kappa")
        kappa_dot = self.block(obs, "kappa_dot")
        gamma = self.turning_bias(obs, state)
        psihat = estimate_phase(kappa, kappa_dot, p.omega, gamma) if p.omega > 0 else np.zeros_like(kappa)
        psi = np.empty_like(psihat)
        psi[:, :-1] = psihat[:, 1:] - self.delta
        if p.closure == "circulant":
            psi[:, -1] = psihat[:, 0] - self.delta
        else:
            psi[:, -1] = self.clock_phase(t)[:, -1]
        kappa_des, kappa_dot_des = self.desired(self.start_up(psi, t), gamma)
        integral = state[:, 1 : 1 + self.n_outputs]
        u = pid_law(self.gait, self.layout.dt, kappa, kappa_dot, kappa_des, kappa_dot_des, integral)
        state[:, 0] = t + self.layout.dt
        return u, np.abs(kappa_des - kappa)
