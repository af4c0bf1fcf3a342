"""Actual-curvature PID on a centralized clock (docs/model.md §7)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from soft_snake_gym.gaits import SerpenoidParams
from soft_snake_gym.policies.open_loop import _SerpenoidPolicy

__all__ = ["CurvaturePID", "PIDParams", "pid_law"]


@dataclass(frozen=True)
class PIDParams(SerpenoidParams):
    """Serpenoid gait plus PID gains and saturation.

    Attributes:
        Kp, Kd, Ki: gains on e, e_dot and the integral of e, e = kappa_des - kappa
            (thesis: 10, 1, 5; (10, 2, 1) is the second set, needed at E_bend = 1.87e4 Pa).
        saturation: |u| <= saturation * alpha * omega (thesis: 1.5).
    """

    Kp: float = 10.0
    Kd: float = 1.0
    Ki: float = 5.0
    saturation: float = 1.5

    def __post_init__(self) -> None:
        """Check the gait's values, the gains and the saturation."""
        super().__post_init__()
        for name in ("Kp", "Kd", "Ki"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must be >= 0")
        if not self.saturation > 0:
            raise ValueError(f"saturation = {self.saturation!r} must be > 0 (|u| <= saturation alpha omega)")


def pid_law(
    p: PIDParams,
    dt: float,
    kappa: np.ndarray,
    kappa_dot: np.ndarray,
    kappa_des: np.ndarray,
    kappa_dot_des: np.ndarray,
    integral: np.ndarray,
) -> np.ndarray:
    """``u = kappa_dot_des + Kp e + Kd e_dot + Ki int e``, saturated (docs/model.md §7).

    Updates ``integral`` in place (rectangle rule, before use); all arrays (n_envs, N-2).
    """
    e = kappa_des - kappa
    integral += e * dt
    u = kappa_dot_des + p.Kp * e + p.Kd * (kappa_dot_des - kappa_dot) + p.Ki * integral
    limit = p.saturation * p.alpha * p.omega
    return np.clip(u, -limit, limit)


class CurvaturePID(_SerpenoidPolicy):
    """PID on the measured curvature, reference from a centralized clock (docs/model.md §7).

    State per env: ``[t, integral_1 .. integral_(N-2)]``.

    Args:
        env: SoftEel env (or a DummyVecEnv of them).
        alpha, omega, delta, gamma, psi0, Kp, Kd, Ki, saturation: see :class:`PIDParams`.
    """

    name = "pid"
    Params = PIDParams

    def _control(self, obs, state):
        t = state[:, 0].copy()
        kappa = self.block(obs, "kappa")
        kappa_des, kappa_dot_des = self.desired(self.clock_phase(t), self.turning_bias(obs, state))
        integral = state[:, 1 : 1 + self.n_outputs]
        u = pid_law(
            self.gait,
            self.layout.dt,
            kappa,
            self.block(obs, "kappa_dot"),
            kappa_des,
            kappa_dot_des,
            integral,
        )
        state[:, 0] = t + self.layout.dt
        return u, np.abs(kappa_des - kappa)
