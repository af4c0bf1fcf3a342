"""Traveling-wave gaits (docs/model.md §6).

The serpenoid for swimming, the length waves (sinusoidal and peristaltic pulse) for inching.

All functions are plain numpy on arrays, so policies and tests share them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from soft_snake_gym.physics.geometry import polyline_crosses
from soft_snake_gym.physics.simulator import body_from_curvature

__all__ = [
    "SerpenoidParams",
    "serpenoid_phase",
    "serpenoid",
    "serpenoid_on_nodes",
    "length_wave",
    "pulse_wave",
    "max_serpenoid_amplitude",
]


@dataclass(frozen=True)
class SerpenoidParams:
    """Serpenoid gait (docs/model.md §6), thesis defaults.

    Attributes:
        alpha: amplitude of the turning angle [rad] (pi/6).
        omega: temporal frequency [rad/s] (2 pi / 3).
        delta: phase offset between neighbouring nodes [rad]; None: 2 pi / (N - 2), one
            wave along the body (pi/4 for N = 10).
        gamma: turning bias [rad] (0).
        psi0: phase of the clock at t = 0 [rad] (0).

    On a refined rod (``Rod.refined``), ``alpha``, ``delta`` and ``gamma`` are those of the
    robot as designed and are mapped onto arc length: each node runs ``alpha l / l_d``,
    ``delta l / l_d`` and ``gamma l / l_d`` (``soft_snake_gym.gaits.serpenoid_on_nodes``), so
    that the body wave is the same whatever N. The controllers' gains need no scaling: every
    term of their laws is a per-node turning angle (or its rate or integral), the continuous
    curvature times the edge length, so the law divided by ``l`` is the same law on
    curvatures per unit length with the same gains [1/s]; the saturation
    ``1.5 alpha omega`` follows the mapped ``alpha``.
    """

    alpha: float = math.pi / 6
    omega: float = 2 * math.pi / 3
    delta: float | None = None
    gamma: float = 0.0
    psi0: float = 0.0

    def __post_init__(self) -> None:
        """Check that ``alpha`` is in [0, pi) and ``omega >= 0``."""
        if not 0 <= self.alpha < math.pi:
            raise ValueError(f"alpha = {self.alpha!r} rad must be in [0, pi)")
        if not self.omega >= 0:
            raise ValueError(f"omega = {self.omega!r} rad/s must be >= 0")


def serpenoid_phase(t: float, n_interior: int, omega: float, delta: float, psi0: float = 0.0) -> np.ndarray:
    """Centralized clock ``psi_j = omega t + delta j + psi0`` for interior nodes j = 1..N-2."""
    return omega * t + delta * np.arange(1, n_interior + 1) + psi0


def serpenoid_on_nodes(
    alpha: float, delta: float | None, n_nodes: int, design_nodes: int | None = None, gamma: float = 0.0
) -> tuple[float, float, float]:
    """Per-node amplitude, phase offset and bias of a serpenoid on a (possibly refined) rod.

    ``alpha``, ``delta`` and ``gamma`` are given per node of the robot as designed,
    ``design_nodes`` nodes with edges of length ``l_d`` (``Rod.refined_from``; None:
    ``n_nodes``, no refinement), and ``delta = None`` is one wave along its interior,
    ``2 pi / (design_nodes - 2)`` (docs/model.md §6). They describe a continuous body wave on arc
    length ``s``: turning angle per unit length ``(alpha sin(omega t + 2 pi s / lambda +
    psi0) + gamma) / l_d`` with wavelength ``lambda = 2 pi l_d / delta``. On a rod of
    ``n_nodes`` nodes with the same length, edges of ``l = l_d (design_nodes - 1) / (n_nodes -
    1)`` and interior node j at ``s_j = j l``, that wave is the per-node amplitude
    ``alpha l / l_d``, phase offset ``delta l / l_d`` and bias ``gamma l / l_d``. For an
    unrefined rod they are returned unchanged, bit for bit.

    Returns:
        (alpha_node, delta_node, gamma_node) [rad].
    """
    design = n_nodes if design_nodes is None else design_nodes
    ratio = (design - 1) / (n_nodes - 1)  # l / l_d, exactly 1.0 without refinement
    delta = 2 * math.pi / (design - 2) if delta is None else delta
    return alpha * ratio, delta * ratio, gamma * ratio


def serpenoid(
    psi: np.ndarray, psi_dot: float | np.ndarray, alpha: float, gamma: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Desired curvature and its rate at phases ``psi`` (docs/model.md §6).

    ``phi_des = alpha sin(psi) + gamma``, ``kappa_des = 2 tan(phi_des / 2)``,
    ``kappa_dot_des = alpha psi_dot cos(psi) sec^2(phi_des / 2)``.

    Returns:
        (kappa_des, kappa_dot_des), each shaped like ``psi`` [-, 1/s].
    """
    phi = alpha * np.sin(psi) + gamma
    half = 0.5 * phi
    return 2.0 * np.tan(half), alpha * psi_dot * np.cos(psi) / np.cos(half) ** 2


def max_serpenoid_amplitude(n_nodes: int, delta: float, gamma: float = 0.0) -> float:
    """Largest ``alpha`` whose serpenoid body does not self-intersect at any phase.

    By bisection to 1e-4 rad, for the body with equal edges (docs/model.md §6).
    """
    lbar = np.ones(n_nodes - 1)

    def crosses(alpha: float) -> bool:
        for psi0 in np.linspace(0.0, 2 * np.pi, 24, endpoint=False):
            k, _ = serpenoid(serpenoid_phase(0.0, n_nodes - 2, 0.0, delta, psi0), 0.0, alpha, gamma)
            if polyline_crosses(body_from_curvature(k, lbar)):
                return True
        return False

    lo, hi = 0.0, np.pi * 0.999
    if not crosses(hi):
        return hi
    while hi - lo > 1e-4:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if crosses(mid) else (mid, hi)
    return lo


def length_wave(
    t: float, n_edges: int, l0: float, eps: float, omega: float, delta_l: float, direction: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Compression wave of the rest lengths (docs/model.md §6).

    ``lbar_des,k = l0 (1 - eps (1 + sin(omega t - direction delta_l k)) / 2)``; with
    ``direction = +1`` the wave travels from tail to head, with -1 from head to tail.

    Returns:
        (lbar_des, lbar_dot_des), (n_edges,) each [m, m/s].
    """
    if direction not in (1, -1):
        raise ValueError(f"direction = {direction!r} must be +1 (tail to head) or -1 (head to tail)")
    arg = omega * t - direction * delta_l * np.arange(n_edges)
    return l0 * (1.0 - 0.5 * eps * (1.0 + np.sin(arg))), -0.5 * l0 * eps * omega * np.cos(arg)


def pulse_wave(
    t: float,
    n_edges: int,
    l0: float,
    eps: float,
    omega: float,
    delta_l: float,
    duty: float,
    direction: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """Peristaltic pulse of the rest lengths (docs/model.md §6).

    A raised-cosine compression pulse that occupies a fraction ``duty`` of each period, the rest of
    the time at ``l0``.

    With the phase ``theta_k = (omega t - direction delta_l k) mod 2 pi`` and
    ``w = 2 pi duty``::

        c_k = (1 - cos(theta_k / duty)) / 2   if theta_k < w, else 0
        lbar_des,k = l0 (1 - eps c_k)
        lbar_dot_des,k = -l0 eps omega sin(theta_k / duty) / (2 duty)   if theta_k < w, else 0

    ``c`` rises from 0 to full compression ``eps`` at the middle of the pulse and back, with a
    zero slope at both ends, so ``lbar_dot_des`` is continuous and bounded by
    ``0.5 l0 eps omega / duty`` (1/duty times the sinusoidal wave's peak rate). With
    ``delta_l = 2 pi / n_edges`` (one period along the body) about ``duty * n_edges`` edges
    are in the pulse at any time; they travel tail to head for ``direction = +1``. ``duty = 1``
    is the sinusoidal :func:`length_wave`, a quarter period later.

    Args:
        t: time [s].
        n_edges: number of edges N - 1.
        l0: uncompressed edge length [m].
        eps: compression at the middle of the pulse, a fraction of ``l0``.
        omega: temporal frequency [rad/s].
        delta_l: phase offset between neighbouring edges [rad].
        duty: fraction of the period (and, at one wave per body, of the edges) in the pulse,
            in (0, 1].
        direction: +1 (tail to head) or -1 (head to tail).

    Returns:
        (lbar_des, lbar_dot_des), (n_edges,) each [m, m/s].
    """
    if direction not in (1, -1):
        raise ValueError(f"direction = {direction!r} must be +1 (tail to head) or -1 (head to tail)")
    if not 0.0 < duty <= 1.0:
        raise ValueError(f"duty = {duty!r} must be in (0, 1]: the fraction of the edges in the pulse")
    theta = np.mod(omega * t - direction * delta_l * np.arange(n_edges), 2.0 * np.pi)
    inside = theta < 2.0 * np.pi * duty
    arg = theta / duty
    c = np.where(inside, 0.5 * (1.0 - np.cos(arg)), 0.0)
    c_dot = np.where(inside, 0.5 * omega * np.sin(arg) / duty, 0.0)
    return l0 * (1.0 - eps * c), -l0 * eps * c_dot
