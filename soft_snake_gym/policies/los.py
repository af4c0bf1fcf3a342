"""Steering: a heading controller on the turning bias, and line-of-sight guidance (ILOS).

The classical answer for underwater snake robots (Kelasidi, Liljebäck, Pettersen and Gravdahl,
IEEE Transactions on Robotics 33(3), 2017): a serpenoid gait whose turning bias ``gamma``
(docs/model.md §6) is set by a heading controller, and a heading reference from integral
line-of-sight guidance. Here the gait is tracked by the curvature PID of
:class:`~soft_snake_gym.policies.pid.CurvaturePID`, and the heading controller is a PD law with
saturation on the heading error ``e = psi_ref - psi`` [rad], low-pass filtered (the tail-to-head
chord, the robot's heading, swings with the gait)::

    e_f' = (e - e_f) / tau
    gamma = clip(Kp_heading e_f + Kd_heading e_f', -gamma_max, gamma_max)

A positive ``gamma`` turns the eel to its left (counter-clockwise; measured at the thesis gait:
0.09, 0.13 and 0.23 rad/s of turning at gamma = 0.05, 0.1, 0.2 rad, against a drift of
0.04 rad/s at gamma = 0).

The heading reference (both read from the observation of the navigation envs):

- ``SoftEelGoal-v0``: pure pursuit, ``psi_ref`` the bearing of the target (the observed
  ``goal_direction_body`` is ``(cos, sin)`` of ``psi_ref - psi`` itself);
- ``SoftEelPath-v0``: integral line-of-sight, with the path direction ``psi_p`` (observed relative to
  the heading) and the cross-track error ``y`` (positive with the robot left of the path)::

      psi_ref = psi_p - atan((y + sigma y_int) / lookahead)
      y_int' = lookahead y / ((y + sigma y_int)^2 + lookahead^2)

  The integral term cancels a steady drift (here the gait's own turning) that would otherwise
  leave a constant cross-track error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from soft_snake_gym.policies.base import PolicyEnvMismatch
from soft_snake_gym.policies.pid import CurvaturePID, PIDParams

__all__ = ["HeadingController", "LOSGuidance", "LOSParams", "heading_error", "los_reference"]


@dataclass(frozen=True)
class HeadingController:
    """PD law with saturation from the heading error to the turning bias.

    Attributes:
        Kp_heading: proportional gain [rad of gamma per rad of heading error].
        Kd_heading: derivative gain [s].
        gamma_max: saturation of ``|gamma|`` [rad].
        tau: time constant of the low-pass filter on the heading error [s].
    """

    Kp_heading: float = 0.6
    Kd_heading: float = 1.0
    gamma_max: float = 0.3
    tau: float = 1.5

    def step(self, error: np.ndarray, filtered: np.ndarray, dt: float) -> np.ndarray:
        """One control step: updates ``filtered`` in place and returns gamma, (n,) [rad].

        Args:
            error: the heading error ``psi_ref - psi``, wrapped to (-pi, pi], (n,) [rad].
            filtered: the filtered error ``e_f``, (n,) [rad], updated in place.
            dt: control step [s].
        """
        rate = (error - filtered) / self.tau
        filtered += rate * dt
        gamma = self.Kp_heading * filtered + self.Kd_heading * rate
        return np.clip(gamma, -self.gamma_max, self.gamma_max)


def heading_error(cos_sin: np.ndarray) -> np.ndarray:
    """The angle of ``(cos, sin)`` rows (n, 2), in (-pi, pi] [rad]."""
    return np.arctan2(cos_sin[:, 1], cos_sin[:, 0])


def los_reference(y: np.ndarray, y_int: np.ndarray, lookahead: float, sigma: float, dt: float) -> np.ndarray:
    """Integral line-of-sight: the heading reference relative to the path direction, (n,) [rad].

    ``-atan((y + sigma y_int) / lookahead)``; updates ``y_int`` in place (forward Euler of its
    law, module docstring).
    """
    shifted = y + sigma * y_int
    y_int += dt * lookahead * y / (shifted * shifted + lookahead * lookahead)
    return -np.arctan2(y + sigma * y_int, lookahead)


@dataclass(frozen=True)
class LOSParams(PIDParams):
    """The curvature PID's gait and gains, the heading controller and the guidance.

    Attributes:
        Kp_heading, Kd_heading, gamma_max, tau: the heading controller (:class:`HeadingController`).
        lookahead: the line-of-sight look-ahead distance ``Delta`` [m] (path following).
        sigma: the integral gain of ILOS [-] (0: plain LOS).

    The defaults were chosen on ``SoftEelPath-v0`` at the thesis gait from a grid (lookahead 0.5,
    0.7, 1, 2 m; Kp_heading 0.3, 0.6, 1; Kd_heading 0, 0.5, 1, 2 s; tau 0.5, 1.5, 3 s; sigma 0 to
    0.2). The heading (the tail-to-head chord, or the mean link angle alike) swings by about
    ±0.17 rad at the gait's frequency; with ``tau = 0.5`` s the derivative passes that swing on
    to gamma, which tracks a line slightly better (mean cross-track error 0.17 m on random lines)
    but spends 1250 J of actuator work in 30 s instead of 370 J, because the gait is then driven
    harder. With ``tau = 1.5`` s: from a 1 m offset the cross-track error is 2 cm at 30 s; on
    random lines (offset within ±1 m, angle within ±pi/6) its mean over 30 s is 0.19 m, 3 cm at
    the end. Larger ``sigma`` winds the integral up during the approach (the error stays near
    1 m for about 15 s at this speed) and overshoots: 5 cm left at 30 s with sigma = 0.02,
    0.2 m with 0.05.
    """

    Kp_heading: float = 0.6
    Kd_heading: float = 1.0
    gamma_max: float = 0.3
    tau: float = 1.5
    lookahead: float = 0.5
    sigma: float = 0.01

    def __post_init__(self) -> None:
        """Check the PID's values, the heading gains and the guidance's."""
        super().__post_init__()
        for name in ("Kp_heading", "Kd_heading", "sigma"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must be >= 0")
        for name in ("gamma_max", "tau", "lookahead"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} = {getattr(self, name)!r} must be > 0")


class LOSGuidance(CurvaturePID):
    """Line-of-sight guidance over a heading controller and the curvature PID (``--policy los``).

    Pure pursuit of the target's bearing in ``SoftEelGoal-v0``, integral line-of-sight (ILOS) in
    ``SoftEelPath-v0`` (module docstring). State per env: ``[t, integral_1 .. integral_(N-2),
    e_f, y_int]``.

    Args:
        env: a SoftEelGoal-v0 or SoftEelPath-v0 env (or a DummyVecEnv of them).
        alpha, omega, delta, psi0, Kp, Kd, Ki, saturation: the gait and the PID
            (:class:`~soft_snake_gym.policies.pid.PIDParams`; the gait's ``gamma`` adds to the
            heading controller's).
        Kp_heading, Kd_heading, gamma_max, tau, lookahead, sigma: see :class:`LOSParams`.
    """

    name = "los"
    Params = LOSParams
    needs = ("kappa", "kappa_dot", "goal_direction_body")
    suggestion = "use it on SoftEelGoal-v0 or SoftEelPath-v0"

    def _setup(self) -> None:
        super()._setup()
        blocks = self.layout.blocks
        if "target_distance" not in blocks and "cross_track_error" not in blocks:
            raise PolicyEnvMismatch(
                f"policy 'los' steers toward a target or along a path, but {self.layout.env_id} has "
                f"neither (it observes {list(blocks)}); use it on SoftEelGoal-v0 or SoftEelPath-v0"
            )
        self.path = "cross_track_error" in blocks
        p = self.params
        self.heading = HeadingController(p.Kp_heading, p.Kd_heading, p.gamma_max, p.tau)
        self.state_size = 1 + self.n_outputs + 2

    def turning_bias(self, obs: np.ndarray, state: np.ndarray) -> np.ndarray:
        """The heading controller's gamma per node, (n_envs, 1) [rad]; updates its memory."""
        p, dt = self.params, self.layout.dt
        error = heading_error(self.block(obs, "goal_direction_body"))
        if self.path:
            y = self.block(obs, "cross_track_error")[:, 0]
            y_int = state[:, -1].copy()
            error = np.angle(np.exp(1j * (error + los_reference(y, y_int, p.lookahead, p.sigma, dt))))
            state[:, -1] = y_int
        filtered = state[:, -2].copy()
        gamma = self.heading.step(error, filtered, dt)
        state[:, -2] = filtered
        return (gamma * self.edge_ratio + self.gait.gamma)[:, None]
