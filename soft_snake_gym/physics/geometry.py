"""Geometry of the discrete rod (docs/model.md §2).

Turning angles and curvatures, edge frames, lengths and their rates, node tangents, and
self-intersection. Kernels on flat interleaved positions ``q`` and velocities ``v`` (2N,); outputs
are written in place.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy", _nrt=False)
def turning(q, j):
    """Turning quantities at interior node j (docs/model.md §2).

    Returns:
        (kappa, g0x, g0y, g1x, g1y, g2x, g2y, ta, tb, 1/la, 1/lb) packed as: kappa, the gradient
        d phi / d x of nodes j-1, j, j+1, and the unit tangents and reciprocal lengths of both edges.
    """
    ax = q[2 * j] - q[2 * j - 2]
    ay = q[2 * j + 1] - q[2 * j - 1]
    bx = q[2 * j + 2] - q[2 * j]
    by = q[2 * j + 3] - q[2 * j + 1]
    ia = 1.0 / math.sqrt(ax * ax + ay * ay)
    ib = 1.0 / math.sqrt(bx * bx + by * by)
    return _turning_of(ia, ax * ia, ay * ia, ib, bx * ib, by * ib)


@njit(cache=True, inline="always", error_model="numpy")
def turning_at(geo, j):
    """:func:`turning` from the edge geometry ``geo`` of :func:`edge_geometry` (bit for bit the same)."""
    return _turning_of(
        geo[0, 2 * j - 1],
        geo[1, 2 * j - 2],
        geo[1, 2 * j - 1],
        geo[0, 2 * j + 1],
        geo[1, 2 * j],
        geo[1, 2 * j + 1],
    )


@njit(cache=True, inline="always", error_model="numpy")
def _turning_of(ia, tax, tay, ib, tbx, tby):
    """:func:`turning`'s quantities from the reciprocal lengths and unit tangents of the node's two edges."""
    cross = tax * tby - tay * tbx
    dot = tax * tbx + tay * tby
    kappa = 2.0 * cross / (1.0 + dot)
    # n = (-t_y, t_x); d phi/d x_{j-1} = n_a/l_a, d phi/d x_{j+1} = n_b/l_b
    g0x, g0y = -tay * ia, tax * ia
    g2x, g2y = -tby * ib, tbx * ib
    return kappa, g0x, g0y, -g0x - g2x, -g0y - g2y, g2x, g2y, tax, tay, tbx, tby, ia, ib


@njit(cache=True, error_model="numpy", _nrt=False)
def edge_geometry(q, geo):
    """Every edge's length, its reciprocal and unit tangent, once for the kernels that need them many times.

    Writes ``geo[0, 2k:2k+2]`` = (``l_k`` [m], ``1/l_k``) and ``geo[1, 2k:2k+2]`` = ``t_k`` for the
    N-1 edges of ``q`` (``geo``: at least (2, 2N-2)); one division an edge, the kernels multiply
    by the reciprocal. :func:`turning_at` and :func:`edge_frame_at` read them and
    give bit for bit what :func:`turning` and :func:`edge_frame` compute from ``q``.
    """
    for k in range(q.size // 2 - 1):
        ex = q[2 * k + 2] - q[2 * k]
        ey = q[2 * k + 3] - q[2 * k + 1]
        l = math.sqrt(ex * ex + ey * ey)
        il = 1.0 / l
        geo[0, 2 * k] = l
        geo[0, 2 * k + 1] = il
        geo[1, 2 * k] = ex * il
        geo[1, 2 * k + 1] = ey * il


@njit(cache=True, inline="always", error_model="numpy")
def turning_rate(g0x, g0y, g1x, g1y, g2x, g2y, v, j):
    """Rate of node j's turning angle, ``d phi_j/dt = (d phi_j/d x) . v`` [rad/s] (docs/model.md §2).

    The gradient over nodes j-1, j, j+1 is :func:`turning`'s ``g0``, ``g1``, ``g2``.
    """
    return (
        g0x * v[2 * j - 2]
        + g0y * v[2 * j - 1]
        + g1x * v[2 * j]
        + g1y * v[2 * j + 1]
        + g2x * v[2 * j + 2]
        + g2y * v[2 * j + 3]
    )


@njit(cache=True, inline="always", error_model="numpy")
def edge_frame(q, v, i):
    """Edge i's length, unit tangent, normal and mean velocity, as (l, tx, ty, nx, ny, vx, vy, vt, vn).

    The length is ``l``, the unit tangent ``t`` and the normal ``n = (-t_y, t_x)``; the mean
    velocity is ``v^i = (v[i] + v[i+1]) / 2`` with components ``v_t``, ``v_n``
    (docs/model.md §2, §4).
    """
    ex = q[2 * i + 2] - q[2 * i]
    ey = q[2 * i + 3] - q[2 * i + 1]
    l = math.sqrt(ex * ex + ey * ey)
    il = 1.0 / l
    return _frame_of(l, ex * il, ey * il, v, i)


@njit(cache=True, inline="always", error_model="numpy")
def edge_frame_at(geo, v, i):
    """:func:`edge_frame` from the edge geometry ``geo`` of :func:`edge_geometry` (bit for bit the same)."""
    return _frame_of(geo[0, 2 * i], geo[1, 2 * i], geo[1, 2 * i + 1], v, i)


@njit(cache=True, inline="always", error_model="numpy")
def _frame_of(l, tx, ty, v, i):
    """:func:`edge_frame`'s quantities from edge i's length and unit tangent."""
    nx, ny = -ty, tx
    vx = 0.5 * (v[2 * i] + v[2 * i + 2])
    vy = 0.5 * (v[2 * i + 1] + v[2 * i + 3])
    return l, tx, ty, nx, ny, vx, vy, vx * tx + vy * ty, vx * nx + vy * ny


@njit(cache=True, error_model="numpy", _nrt=False)
def curvatures(q, kappa):
    """Discrete curvature ``kappa_j = 2 tan(phi_j/2)`` of the interior nodes, (N-2,) [-]."""
    for j in range(1, q.size // 2 - 1):
        kappa[j - 1] = turning(q, j)[0]


@njit(cache=True, error_model="numpy", _nrt=False)
def curvature_rates(q, v, kdot):
    """Exact curvature rate ``(1 + kappa^2/4)(theta_dot^j - theta_dot^(j-1))``, (N-2,) [1/s]."""
    for j in range(1, q.size // 2 - 1):
        kdot[j - 1] = _curvature_rate(turning(q, j), v, j)


@njit(cache=True, error_model="numpy", _nrt=False)
def curvatures_and_rates_at(geo, v, kappa, kdot):
    """:func:`curvatures` and :func:`curvature_rates` from the edge geometry ``geo`` of :func:`edge_geometry`."""
    for j in range(1, v.size // 2 - 1):
        turn = turning_at(geo, j)
        kappa[j - 1] = turn[0]
        kdot[j - 1] = _curvature_rate(turn, v, j)


@njit(cache=True, inline="always", error_model="numpy")
def _curvature_rate(turn, v, j):
    k, g0x, g0y, g1x, g1y, g2x, g2y = turn[:7]
    return (1.0 + 0.25 * k * k) * turning_rate(g0x, g0y, g1x, g1y, g2x, g2y, v, j)


@njit(cache=True, error_model="numpy", _nrt=False)
def edge_lengths(q, out):
    """Current edge lengths ``|e^k|``, (N-1,) [m]."""
    for k in range(q.size // 2 - 1):
        out[k] = math.hypot(q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1])


@njit(cache=True, error_model="numpy", _nrt=False)
def edge_length_rates(q, v, out):
    """Rates ``t^k . (v[k+1] - v[k])`` of the edge lengths, (N-1,) [m/s]."""
    for k in range(q.size // 2 - 1):
        ex = q[2 * k + 2] - q[2 * k]
        ey = q[2 * k + 3] - q[2 * k + 1]
        l = math.hypot(ex, ey)
        out[k] = (ex * (v[2 * k + 2] - v[2 * k]) + ey * (v[2 * k + 3] - v[2 * k + 1])) / l


@njit(cache=True, error_model="numpy", _nrt=False)
def node_tangent(q, i):
    """Unit tangent of the body at node i: along the sum of its edges' unit tangents."""
    N = q.size // 2
    tx, ty = 0.0, 0.0
    for k in (i - 1, i):
        if 0 <= k < N - 1:
            ex, ey = q[2 * k + 2] - q[2 * k], q[2 * k + 3] - q[2 * k + 1]
            l = math.sqrt(ex * ex + ey * ey)
            tx += ex / l
            ty += ey / l
    l = math.sqrt(tx * tx + ty * ty)
    return tx / l, ty / l


@njit(cache=True, error_model="numpy", _nrt=False)
def _segments_cross(q, a, b):
    """True if edges a and b cross properly (a shared end or a mere touch does not count)."""
    p1x, p1y, p2x, p2y = q[2 * a], q[2 * a + 1], q[2 * a + 2], q[2 * a + 3]
    p3x, p3y, p4x, p4y = q[2 * b], q[2 * b + 1], q[2 * b + 2], q[2 * b + 3]
    d1 = (p2x - p1x) * (p3y - p1y) - (p2y - p1y) * (p3x - p1x)
    d2 = (p2x - p1x) * (p4y - p1y) - (p2y - p1y) * (p4x - p1x)
    d3 = (p4x - p3x) * (p1y - p3y) - (p4y - p3y) * (p1x - p3x)
    d4 = (p4x - p3x) * (p2y - p3y) - (p4y - p3y) * (p2x - p3x)
    return d1 * d2 < 0.0 and d3 * d4 < 0.0


@njit(cache=True, error_model="numpy", _nrt=False)
def self_intersects(q, keys, order):
    """Sweep and prune over the edges' x-extents.

    ``order`` (N-1,) persists between calls, so the insertion sort is nearly linear for a body that
    moves a little each step.
    """
    ne = q.size // 2 - 1
    for e in range(ne):
        keys[e] = min(q[2 * e], q[2 * e + 2])
    for i in range(1, ne):
        o = order[i]
        kv = keys[o]
        j = i - 1
        while j >= 0 and keys[order[j]] > kv:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = o
    for ii in range(ne):
        a = order[ii]
        xmax = max(q[2 * a], q[2 * a + 2])
        for jj in range(ii + 1, ne):
            b = order[jj]
            if keys[b] > xmax:
                break
            if abs(a - b) >= 2 and _segments_cross(q, a, b):
                return True
    return False


def polyline_crosses(x: np.ndarray) -> bool:
    """True if the polyline through the points ``x`` (n, 2) [m] crosses itself.

    Two of its segments that share no point cross properly (:func:`self_intersects`, outside a
    simulator).
    """
    q = np.ascontiguousarray(x, dtype=np.float64).ravel()
    ne = q.size // 2 - 1
    return bool(self_intersects(q, np.empty(ne), np.arange(ne)))
