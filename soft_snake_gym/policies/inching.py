"""Inching on land (docs/model.md §6-§7): a compression wave of the rest lengths.

``wave="pulse"`` (default): the peristaltic pulse of :func:`soft_snake_gym.gaits.pulse_wave`,
a raised-cosine compression of depth ``eps`` over a fraction ``duty`` of the edges, the others
at ``l0`` (anchored). ``wave="sine"``: ``lbar_des,k(t) = l0 (1 - eps (1 + sin(omega t -
direction delta_l k)) / 2)``, every edge changing at once.

Measured on the converged contact model (thesis worm, mu_s = 1.15, mu_d = 0.8, 10 s, eps =
0.3, omega = 2 pi, ``delta_l = 2 pi / 9``, ``direction = +1``: the wave travels from tail to
head): the pulse (duty 0.6) moves the worm **forward, toward the head**, by 1.24 m open loop
and 1.23 m under the inching PID at h = 0.01 s (1.24 and 1.24 m with the step divided by 16;
2026-12-06); the sine wave, which anchors little, by a few millimetres either way, no more
than the stick-slip chatter. The pulse is therefore the default. ``direction = -1`` reverses either
wave; for ``delta_l`` above pi the direction flips (the wave aliases to the other direction).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np

from soft_snake_gym.gaits import length_wave, pulse_wave
from soft_snake_gym.policies.base import BaselinePolicy

__all__ = ["InchingWave", "InchingPID", "InchingParams", "InchingPIDParams", "PULSE_DUTY"]

PULSE_DUTY = 0.6
"""``duty`` of ``wave="pulse"`` when none is given."""


@dataclass(frozen=True)
class InchingParams:
    """Length-wave gait.

    Attributes:
        eps: fraction of compression, in (0, 1) (0.3).
        omega: temporal frequency [rad/s] (2 pi).
        delta_l: phase offset between neighbouring edges [rad]; None: 2 pi / (N - 1), one
            wave along the body whatever N.
        direction: +1 the wave travels tail to head (moves the worm toward the head), -1 the
            reverse.
        l0: uncompressed edge length [m]; None: the env's rest edge length.
        rest_gain: ``r`` [1/s] of the open loop's ``u = lbar_dot_des + r (lbar_des - lbar)`` (10;
            0: the bare law). ``lbar`` is the controller's own command, not a measurement, so
            this stays open loop in the body; it removes the offset a start at ``l0`` (the
            env's default) would otherwise leave in the rest lengths for the whole episode.
            The closed loop (:class:`InchingPID`) does not use it: its feedback on the
            measured length removes that offset already.
        wave: ``"pulse"`` (the peristaltic pulse, default: it moves the worm furthest) or
            ``"sine"`` (the sinusoidal wave of the sources).
        duty: fraction of the edges in the pulse, in (0, 1]; only with ``wave="pulse"``
            (None: :data:`PULSE_DUTY`). The pulse's peak rate is ``0.5 l0 eps omega / duty``
            (0.17 m/s / duty at the defaults); above the env's ``max_length_rate`` (0.3 m/s)
            the env clips it, and the policy warns.

    On a refined rod (``Rod.refined``), a given ``delta_l`` or ``l0`` is that of the robot as
    designed, and each edge runs ``delta_l l / l_d`` and ``l0 l / l_d``: the same wave on arc
    length (``eps`` and the gains [1/s] need no mapping).
    """

    eps: float = 0.3
    omega: float = 2 * math.pi
    delta_l: float | None = None
    direction: int = 1
    l0: float | None = None
    rest_gain: float = 10.0
    wave: Literal["sine", "pulse"] = "pulse"
    duty: float | None = None

    def __post_init__(self) -> None:
        """Check ``wave``, ``duty`` and the other values."""
        if self.wave not in ("sine", "pulse"):
            raise ValueError(f"wave = {self.wave!r} is unknown; use 'sine' or 'pulse'")
        if self.duty is not None:
            if self.wave != "pulse":
                raise ValueError(
                    f"duty = {self.duty!r} applies to wave='pulse' only; add wave=pulse or drop duty"
                )
            if not 0 < self.duty <= 1:
                raise ValueError(
                    f"duty = {self.duty!r} must be in (0, 1]: the fraction of the edges in the pulse"
                )
        if not 0 <= self.eps < 1:
            raise ValueError(f"eps = {self.eps!r} must be in [0, 1)")
        if not self.omega >= 0:
            raise ValueError(f"omega = {self.omega!r} rad/s must be >= 0")
        if self.direction not in (1, -1):
            raise ValueError(f"direction = {self.direction!r} must be +1 or -1")
        if not self.rest_gain >= 0:
            raise ValueError(f"rest_gain = {self.rest_gain!r} 1/s must be >= 0")
        if self.l0 is not None and not self.l0 > 0:
            raise ValueError(f"l0 = {self.l0!r} m must be > 0")


@dataclass(frozen=True)
class InchingPIDParams(InchingParams):
    """Length wave plus the proportional gain on the measured edge length.

    Attributes:
        Kp: gain [1/s] in ``u = lbar_dot_des + Kp (lbar_des - |e|)`` (10).
    """

    Kp: float = 10.0

    def __post_init__(self) -> None:
        """Check the wave's values and ``Kp >= 0``."""
        super().__post_init__()
        if not self.Kp >= 0:
            raise ValueError(f"Kp = {self.Kp!r} 1/s must be >= 0")


class InchingWave(BaselinePolicy):
    """Open loop ``u_l = lbar_dot_des + rest_gain (lbar_des - lbar)`` (docs/model.md §7).

    The bare ``u_l = lbar_dot_des`` once the rest lengths are on the wave. State per env: ``[t]``.

    Args:
        env: SoftWorm env (or a DummyVecEnv of them).
        eps, omega, delta_l, direction, l0, rest_gain, wave, duty: see :class:`InchingParams`.
    """

    name = "inching"
    Params = InchingParams
    needs = ("edge_lengths", "lbar")
    controls = "edge lengths"
    suggestion = "use 'open-loop', 'pid' or 'decentralized' on SoftEel-v0"

    def _setup(self) -> None:
        self.n_outputs = self.layout.n_nodes - 1
        p = self.params
        ratio = (self.layout.design_nodes - 1) / self.n_outputs  # l / l_d
        self.delta_l = 2 * math.pi / self.n_outputs if p.delta_l is None else p.delta_l * ratio
        self.l0 = self.layout.edge_length if p.l0 is None else p.l0 * ratio
        self.duty = (PULSE_DUTY if p.duty is None else p.duty) if p.wave == "pulse" else 1.0
        self.state_size = 1
        peak = 0.5 * self.l0 * p.eps * p.omega / self.duty
        if peak > self.layout.action_scale:
            warnings.warn(
                f"{self.name}: the {p.wave} wave's peak rate 0.5 l0 eps omega / duty = {peak:.3g} m/s "
                f"exceeds the env's max_length_rate = {self.layout.action_scale:.3g} m/s and will be "
                "clipped; raise max_length_rate or duty, or lower eps or omega",
                stacklevel=3,
            )

    def desired(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(lbar_des, lbar_dot_des)`` at times t (n_envs,), each (n_envs, N-1)."""
        p = self.params
        if p.wave == "pulse":
            out = [
                pulse_wave(ti, self.n_outputs, self.l0, p.eps, p.omega, self.delta_l, self.duty, p.direction)
                for ti in t
            ]
        else:
            out = [
                length_wave(ti, self.n_outputs, self.l0, p.eps, p.omega, self.delta_l, p.direction)
                for ti in t
            ]
        return np.array([o[0] for o in out]), np.array([o[1] for o in out])

    def _control(self, obs, state):
        t = state[:, 0].copy()
        lbar_des, lbar_dot_des = self.desired(t)
        lengths = self.block(obs, "edge_lengths")
        state[:, 0] = t + self.layout.dt
        return self._law(lbar_des, lbar_dot_des, lengths, self.block(obs, "lbar")), np.abs(lbar_des - lengths)

    def _law(self, lbar_des, lbar_dot_des, lengths, lbar):
        return lbar_dot_des + self.params.rest_gain * (lbar_des - lbar)


class InchingPID(InchingWave):
    """Closed loop on the measured edge length (docs/model.md §7).

    ``u_l,k = lbar_dot_des,k + Kp (lbar_des,k - |e^k|)``.

    Args:
        env: SoftWorm env (or a DummyVecEnv of them).
        eps, omega, delta_l, direction, l0, wave, duty, Kp: see :class:`InchingPIDParams`.
    """

    name = "inching-pid"
    Params = InchingPIDParams

    def _law(self, lbar_des, lbar_dot_des, lengths, lbar):
        return lbar_dot_des + self.params.Kp * (lbar_des - lengths)
