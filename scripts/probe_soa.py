"""Robots innermost (structure of arrays): does numba vectorize the step's kernels across robots?

The first measurement for a structure-of-arrays batched kernel (docs/performance_history.md, "The
layout and the vectorizer"), on eels taken from random-action episodes, each kernel with the
package's own arithmetic:

1. The elastic and damping forces of ``forces.assemble`` (no Jacobian, no water), three ways:
   - per robot: ``assemble`` itself, robot by robot (the package's layout);
   - fused: robot index innermost, each loop adding straight into the force rows of the nodes
     it pushes (two per edge, three per bending node);
   - split: robot index innermost, each loop writing its terms into fixed rows of a scratch
     array, then adding each into its force row in a loop of its own.
2. The same forces with the water's drag and the drag power (``assemble(water=True)``), the
   drag split the same way.
3. The forces with their Jacobian (``assemble(jac=True)``), the split carried on to the band:
   each node's quantities into scratch rows, then one loop per band entry; over the whole batch,
   and over blocks of 4, 8 and 16 robots (every array (blocks, ..., lanes), a block's band in L1).
4. Backward Euler's whole residual in water, with and without its Jacobian (``_be_residual``:
   ``assemble``, the mass, the water's momentum), robot by robot and by the package's blocks
   of 16 (``physics.lanes``: flat arrays with constant strides, straight-line code per lane),
   the gathering of each block from the robots' arrays included.
5. The Newton step's linear algebra: each robot's backward-Euler Jacobian (water, h = 0.01 s)
   factored and solved by ``band_factor`` and ``band_solve``, robot by robot, with the robot
   index innermost without row exchanges (a robot that would need one is flagged, to be
   redone robot by robot), and by ``physics.lanes``' blocks of 16.

Every variant must give bitwise the same forces, powers, Jacobians, factors and solutions
(exit 1 otherwise). Printed: thread CPU time per robot, medians over interleaved rounds, and
the ratios against the package's kernels in the same process.

    python scripts/probe_soa.py                         # 32 and 256 robots
    NUMBA_LOOP_VECTORIZE=0 python scripts/probe_soa.py  # the same with LLVM's loop vectorizer off
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time

import gymnasium as gym
import numpy as np
from numba import njit

import soft_snake_gym  # noqa: F401 - registers the ids
from soft_snake_gym.physics import banded, forces, lanes, layout, stepper
from soft_snake_gym.physics.banded import KL, KU, PIVOT_THRESHOLD
from soft_snake_gym.physics.layout import SimArrays

LANES = lanes.LANES
"""Robots per block of the package's own kernels (``physics.lanes``)."""
BLOCK_LANES = (4, 8, 16)
"""Robots per block of :func:`blocked_jacobian` (AVX2 holds 4 doubles)."""


@njit(cache=True, error_model="numpy")
def per_robot(q, v, kbar, lbar, prm, F, J, reps):
    """``assemble``'s internal forces, robot by robot; arrays (robots, ...)."""
    geo = np.empty((2, q.shape[1]))  # assemble's edge geometry scratch
    for _ in range(reps):
        for r in range(q.shape[0]):
            F[r, :] = 0.0
            forces.assemble(q[r], v[r], kbar[r], lbar[r], prm[r], F[r], J[r], 0.0, 0.0, False, False, geo)


@njit(cache=True, inline="always", error_model="numpy")
def _edge_force(q, v, k, r, lb, EA, d):
    """Stretching force on node k+1 of robot r, as ``assemble`` computes it (q, v: (2N, robots))."""
    ex = q[2 * k + 2, r] - q[2 * k, r]
    ey = q[2 * k + 3, r] - q[2 * k + 1, r]
    l = math.sqrt(ex * ex + ey * ey)
    tx, ty = ex / l, ey / l
    f = -EA * (l / lb - 1.0)
    f -= d * (tx * (v[2 * k + 2, r] - v[2 * k, r]) + ty * (v[2 * k + 3, r] - v[2 * k + 1, r]))
    return f * tx, f * ty


@njit(cache=True, inline="always", error_model="numpy")
def _turning(q, j, r):
    """``geometry.turning`` at node j of robot r (q: (2N, robots)), the same arithmetic."""
    ax = q[2 * j, r] - q[2 * j - 2, r]
    ay = q[2 * j + 1, r] - q[2 * j - 1, r]
    bx = q[2 * j + 2, r] - q[2 * j, r]
    by = q[2 * j + 3, r] - q[2 * j + 1, r]
    la = math.sqrt(ax * ax + ay * ay)
    lb = math.sqrt(bx * bx + by * by)
    tax, tay = ax / la, ay / la
    tbx, tby = bx / lb, by / lb
    kap = 2.0 * (tax * tby - tay * tbx) / (1.0 + (tax * tbx + tay * tby))
    g0x, g0y = -tay / la, tax / la
    g2x, g2y = -tby / lb, tbx / lb
    return kap, g0x, g0y, -g0x - g2x, -g0y - g2y, g2x, g2y, tax, tay, tbx, tby, la, lb


@njit(cache=True, inline="always", error_model="numpy")
def _turning_rate(v, j, r, g0x, g0y, g1x, g1y, g2x, g2y):
    """``geometry.turning_rate`` at node j of robot r."""
    return (
        g0x * v[2 * j - 2, r]
        + g0y * v[2 * j - 1, r]
        + g1x * v[2 * j, r]
        + g1y * v[2 * j + 1, r]
        + g2x * v[2 * j + 2, r]
        + g2y * v[2 * j + 3, r]
    )


@njit(cache=True, inline="always", error_model="numpy")
def _bending_forces(q, v, j, r, l0, l1, kb0, EI, db):
    """Bending (and its damping) forces on nodes j-1, j, j+1 of robot r, as ``assemble`` computes them."""
    kap, g0x, g0y, g1x, g1y, g2x, g2y = _turning(q, j, r)[:7]
    w = 1.0 + 0.25 * kap * kap
    s = EI / (0.5 * (l0 + l1)) * (kap - kb0) * w
    s += db * w * w * _turning_rate(v, j, r, g0x, g0y, g1x, g1y, g2x, g2y)
    return s * g0x, s * g0y, s * g1x, s * g1y, s * g2x, s * g2y


@njit(cache=True, error_model="numpy")
def fused(q, v, kbar, lbar, EA, EI, d, db, F, reps):
    """Robots innermost; every loop adds into two (edge) or six (bending) rows of F."""
    n2, R = q.shape
    for _ in range(reps):
        F[:, :] = 0.0
        for k in range(n2 // 2 - 1):
            for r in range(R):
                fx, fy = _edge_force(q, v, k, r, lbar[k, r], EA[r], d[r])
                F[2 * k + 2, r] += fx
                F[2 * k + 3, r] += fy
                F[2 * k, r] -= fx
                F[2 * k + 1, r] -= fy
        for j in range(1, n2 // 2 - 1):
            for r in range(R):
                f0, f1, f2, f3, f4, f5 = _bending_forces(
                    q, v, j, r, lbar[j - 1, r], lbar[j, r], kbar[j - 1, r], EI[r], db[r]
                )
                F[2 * j - 2, r] -= f0
                F[2 * j - 1, r] -= f1
                F[2 * j, r] -= f2
                F[2 * j + 1, r] -= f3
                F[2 * j + 2, r] -= f4
                F[2 * j + 3, r] -= f5


@njit(cache=True, error_model="numpy")
def split(q, v, kbar, lbar, EA, EI, d, db, F, reps):
    """Robots innermost; terms into fixed rows of a scratch array, then one loop per force row."""
    n2, R = q.shape
    T = np.empty((6, R))
    for _ in range(reps):
        F[:, :] = 0.0
        for k in range(n2 // 2 - 1):
            for r in range(R):
                T[0, r], T[1, r] = _edge_force(q, v, k, r, lbar[k, r], EA[r], d[r])
            for r in range(R):
                F[2 * k + 2, r] += T[0, r]
            for r in range(R):
                F[2 * k + 3, r] += T[1, r]
            for r in range(R):
                F[2 * k, r] -= T[0, r]
            for r in range(R):
                F[2 * k + 1, r] -= T[1, r]
        for j in range(1, n2 // 2 - 1):
            for r in range(R):
                T[0, r], T[1, r], T[2, r], T[3, r], T[4, r], T[5, r] = _bending_forces(
                    q, v, j, r, lbar[j - 1, r], lbar[j, r], kbar[j - 1, r], EI[r], db[r]
                )
            for m in range(6):
                for r in range(R):
                    F[2 * j - 2 + m, r] -= T[m, r]


@njit(cache=True, error_model="numpy")
def per_robot_water(q, v, kbar, lbar, prm, F, J, power, reps):
    """``assemble``'s internal forces and the water's drag, robot by robot, and the drag power."""
    geo = np.empty((2, q.shape[1]))
    for _ in range(reps):
        for r in range(q.shape[0]):
            F[r, :] = 0.0
            power[r] = forces.assemble(
                q[r], v[r], kbar[r], lbar[r], prm[r], F[r], J[r], 0.0, 0.0, False, True, geo
            )


@njit(cache=True, error_model="numpy")
def split_water(q, v, kbar, lbar, EA, EI, d, db, prm, F, power, reps):
    """The same with robots innermost: :func:`split`'s forces, then the drag, split the same way.

    ``prm`` is (P, robots); the drag per edge as ``assemble`` computes it, its two force
    components into scratch rows, then one loop per force row.
    """
    n2, R = q.shape
    T = np.empty((2, R))
    for _ in range(reps):
        split(q, v, kbar, lbar, EA, EI, d, db, F, 1)
        power[:] = 0.0
        for i in range(n2 // 2 - 1):
            for r in range(R):
                rho, a, b = prm[layout.P_RHO, r], prm[layout.P_A, r], prm[layout.P_B, r]
                ct = 0.25 * rho * math.pi * prm[layout.P_CF, r] * (a + b)  # as assemble
                cn = rho * prm[layout.P_CD, r] * a
                ex = q[2 * i + 2, r] - q[2 * i, r]
                ey = q[2 * i + 3, r] - q[2 * i + 1, r]
                l = math.sqrt(ex * ex + ey * ey)
                tx, ty = ex / l, ey / l
                nx, ny = -ty, tx
                vx = 0.5 * (v[2 * i, r] + v[2 * i + 2, r])
                vy = 0.5 * (v[2 * i + 1, r] + v[2 * i + 3, r])
                vt, vn = vx * tx + vy * ty, vx * nx + vy * ny
                gt = vt + vt * abs(vt)
                gn = vn + vn * abs(vn)
                fx = -ct * l * gt * tx - cn * l * gn * nx
                fy = -ct * l * gt * ty - cn * l * gn * ny
                power[r] -= fx * vx + fy * vy
                T[0, r], T[1, r] = 0.5 * fx, 0.5 * fy
            for m in range(4):  # nodes i and i+1, x and y
                row = 2 * i + m
                for r in range(R):
                    F[row, r] += T[m % 2, r]


# scratch rows of the bending Jacobian, per node and robot (robots innermost)
_ALPHA, _BETA, _C = 0, 1, 2
_G = 3  # g0x, g0y, g1x, g1y, g2x, g2y: rows 3..8
_HA, _HB, _HD = 9, 12, 15  # (h00, h01, h11) of edge a, edge b, and hb - ha
_RV = 18  # r0x, r0y, r1x, r1y, r2x, r2y: rows 18..23
_S, _TS = 24, 27  # the stretching block (s00, s01, s11) and its damping part (t00, t01, t10, t11)
N_SCRATCH = 31


@njit(cache=True, error_model="numpy")
def per_robot_jacobian(q, v, kbar, lbar, prm, F, J, cx, cv, reps):
    """``assemble``'s internal forces and their Jacobian ``cx dF/dq + cv dF/dv``, robot by robot."""
    geo = np.empty((2, q.shape[1]))
    for _ in range(reps):
        for r in range(q.shape[0]):
            F[r, :] = 0.0
            J[r, :, :] = 0.0
            forces.assemble(q[r], v[r], kbar[r], lbar[r], prm[r], F[r], J[r], cx, cv, True, False, geo)


@njit(cache=True, inline="always", error_model="numpy")
def _scatter(J, row, col, T, a, b, c, sign):
    """``J[row, col] += sign T[a] T[b] T[c]`` over robots (``T[a] T[b]`` first, as ``assemble``)."""
    for r in range(J.shape[2]):
        J[row, col, r] += sign * (T[a, r] * T[b, r] * T[c, r])


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_h(J, row, col, T, gi, gj, h, sign):
    """``J[row, col] += alpha gi gj + sign beta h`` over robots (a bending block's entry)."""
    if sign == 0.0:
        for r in range(J.shape[2]):
            J[row, col, r] += T[_ALPHA, r] * T[gi, r] * T[gj, r]
    else:
        for r in range(J.shape[2]):
            J[row, col, r] += T[_ALPHA, r] * T[gi, r] * T[gj, r] + sign * (T[_BETA, r] * T[h, r])


@njit(cache=True, inline="always", error_model="numpy")
def _scatter_row(J, row, col, T, m, sign):
    """``J[row, col] += sign T[m]`` over robots."""
    for r in range(J.shape[2]):
        J[row, col, r] += sign * T[m, r]


@njit(cache=True, error_model="numpy")
def split_jacobian(q, v, kbar, lbar, EA, EI, d, db, F, J, T, cx, cv, reps):
    """The same with robots innermost: the forces as :func:`split`, then the Jacobian.

    Into the band ``J`` (n, width, robots), with each node's quantities in scratch rows ``T``
    and one loop per band entry.
    """
    for _ in range(reps):
        split(q, v, kbar, lbar, EA, EI, d, db, F, 1)
        _lanes_jacobian(q, v, kbar, lbar, EA, EI, d, db, J, T, cx, cv)


@njit(cache=True, error_model="numpy")
def blocked_jacobian(q, v, kbar, lbar, EA, EI, d, db, F, J, T, cx, cv, reps):
    """The same over blocks of a few robots: every array (blocks, ..., lanes), one block at a time.

    A block's band (n, width, lanes) and scratch rows stay in the L1 cache, where the whole
    batch's band (:func:`split_jacobian`) outgrows it.
    """
    for _ in range(reps):
        for b in range(q.shape[0]):
            split(q[b], v[b], kbar[b], lbar[b], EA[b], EI[b], d[b], db[b], F[b], 1)
            _lanes_jacobian(q[b], v[b], kbar[b], lbar[b], EA[b], EI[b], d[b], db[b], J[b], T, cx, cv)


@njit(cache=True, error_model="numpy")
def _lanes_jacobian(q, v, kbar, lbar, EA, EI, d, db, J, T, cx, cv):
    """``assemble``'s Jacobian of the internal forces with robots innermost, into the band ``J``."""
    n2, R = q.shape
    J[:, :, :] = 0.0
    for k in range(n2 // 2 - 1):
        for r in range(R):
            ex = q[2 * k + 2, r] - q[2 * k, r]
            ey = q[2 * k + 3, r] - q[2 * k + 1, r]
            l = math.sqrt(ex * ex + ey * ey)
            tx, ty = ex / l, ey / l
            lb = lbar[k, r]
            f = -EA[r] * (l / lb - 1.0)
            dvx, dvy = v[2 * k + 2, r] - v[2 * k, r], v[2 * k + 3, r] - v[2 * k + 1, r]
            ldot = tx * dvx + ty * dvy
            f -= d[r] * ldot
            a1, a2 = EA[r] / lb, -f / l
            T[_S, r] = cx * (a1 * tx * tx + a2 * (1.0 - tx * tx)) + cv * d[r] * tx * tx
            T[_S + 1, r] = cx * (a1 - a2) * tx * ty + cv * d[r] * tx * ty
            T[_S + 2, r] = cx * (a1 * ty * ty + a2 * (1.0 - ty * ty)) + cv * d[r] * ty * ty
            px, py = cx * d[r] * (dvx - ldot * tx) / l, cx * d[r] * (dvy - ldot * ty) / l
            T[_TS, r], T[_TS + 1, r], T[_TS + 2, r], T[_TS + 3, r] = tx * px, tx * py, ty * px, ty * py
        # add_edge_pattern, then the damping blocks: per entry in assemble's order
        for i, j, sign in ((k, k, -1.0), (k, k + 1, 1.0), (k + 1, k, 1.0), (k + 1, k + 1, -1.0)):
            row, col = 2 * i, 2 * j - 2 * i + KL
            _scatter_row(J, row, col, T, _S, sign)
            _scatter_row(J, row, col + 1, T, _S + 1, sign)
            _scatter_row(J, row + 1, col - 1, T, _S + 1, sign)
            _scatter_row(J, row + 1, col, T, _S + 2, sign)
        for i, j, sign in ((k, k, -1.0), (k, k + 1, 1.0), (k + 1, k, 1.0), (k + 1, k + 1, -1.0)):
            row, col = 2 * i, 2 * j - 2 * i + KL
            for m in range(4):
                _scatter_row(J, row + m // 2, col + m % 2 - m // 2, T, _TS + m, sign)
    for j in range(1, n2 // 2 - 1):
        for r in range(R):
            kap, g0x, g0y, g1x, g1y, g2x, g2y, tax, tay, tbx, tby, la, lbn = _turning(q, j, r)
            kb = EI[r] / (0.5 * (lbar[j - 1, r] + lbar[j, r]))
            dk = kap - kbar[j - 1, r]
            w = 1.0 + 0.25 * kap * kap
            phidot = _turning_rate(v, j, r, g0x, g0y, g1x, g1y, g2x, g2y)
            dbr = db[r]
            s2 = kb * (w * w + dk * 0.5 * kap * w) + dbr * w * w * kap * phidot
            T[_ALPHA, r] = -(cx * s2 + cv * dbr * w * w)
            T[_BETA, r] = -cx * (kb * dk * w + dbr * w * w * phidot)
            T[_C, r] = -cx * dbr * w * w
            T[_G, r], T[_G + 1, r], T[_G + 2, r], T[_G + 3, r] = g0x, g0y, g1x, g1y
            T[_G + 4, r], T[_G + 5, r] = g2x, g2y
            ia, ib = 1.0 / (la * la), 1.0 / (lbn * lbn)
            ha00, ha01, ha11 = 2.0 * tax * tay * ia, (tay * tay - tax * tax) * ia, -2.0 * tax * tay * ia
            hb00, hb01, hb11 = 2.0 * tbx * tby * ib, (tby * tby - tbx * tbx) * ib, -2.0 * tbx * tby * ib
            T[_HA, r], T[_HA + 1, r], T[_HA + 2, r] = ha00, ha01, ha11
            T[_HB, r], T[_HB + 1, r], T[_HB + 2, r] = hb00, hb01, hb11
            T[_HD, r], T[_HD + 1, r], T[_HD + 2, r] = hb00 - ha00, hb01 - ha01, hb11 - ha11
            ux, uy = v[2 * j, r] - v[2 * j - 2, r], v[2 * j + 1, r] - v[2 * j - 1, r]
            wx, wy = v[2 * j + 2, r] - v[2 * j, r], v[2 * j + 3, r] - v[2 * j + 1, r]
            r0x, r0y = ha00 * ux + ha01 * uy, ha01 * ux + ha11 * uy
            r2x, r2y = hb00 * wx + hb01 * wy, hb01 * wx + hb11 * wy
            T[_RV, r], T[_RV + 1, r], T[_RV + 4, r], T[_RV + 5, r] = r0x, r0y, r2x, r2y
            T[_RV + 2, r], T[_RV + 3, r] = -r0x - r2x, -r0y - r2y
        # the damping blocks (a, b) = c g_a r_b^T, nodes a, b in j-1 .. j+1
        for ai in range(3):
            for bi in range(3):
                row, col = 2 * (j - 1 + ai), 2 * (bi - ai) + KL
                gx, gy, rx, ry = _G + 2 * ai, _G + 2 * ai + 1, _RV + 2 * bi, _RV + 2 * bi + 1
                _scatter(J, row, col, T, _C, gx, rx, 1.0)
                _scatter(J, row, col + 1, T, _C, gx, ry, 1.0)
                _scatter(J, row + 1, col - 1, T, _C, gy, rx, 1.0)
                _scatter(J, row + 1, col, T, _C, gy, ry, 1.0)
        # the blocks alpha g_a g_b^T + beta (edge-angle Hessians), in assemble's order
        for ai, bi, h, sign in (
            (0, 0, _HA, -1.0),
            (0, 1, _HA, 1.0),
            (1, 0, _HA, 1.0),
            (0, 2, _HA, 0.0),
            (2, 0, _HA, 0.0),
            (1, 1, _HD, 1.0),
            (1, 2, _HB, -1.0),
            (2, 1, _HB, -1.0),
            (2, 2, _HB, 1.0),
        ):
            row, col = 2 * (j - 1 + ai), 2 * (bi - ai) + KL
            ga, gb = _G + 2 * ai, _G + 2 * bi
            _scatter_h(J, row, col, T, ga, gb, h, sign)
            _scatter_h(J, row, col + 1, T, ga, gb + 1, h + 1, sign)
            _scatter_h(J, row + 1, col - 1, T, ga + 1, gb, h + 1, sign)
            _scatter_h(J, row + 1, col, T, ga + 1, gb + 1, h + 2, sign)


@njit(cache=True, error_model="numpy")
def per_robot_residual(s, dt, jac, res, reps):
    """``stepper._be_residual`` in water robot by robot (stacked ``s``); (|R|^2, max |R|/m, power) into ``res``."""
    s = SimArrays(*s)
    for _ in range(reps):
        for r in range(s.q.shape[0]):
            out = stepper._be_residual(layout.sim_views(s.f[r], s.ibuf[r]), dt, layout.MEDIUM_WATER, jac)
            res[0, r], res[1, r], res[2, r] = out[0], out[1], out[2]


@njit(cache=True, error_model="numpy")
def block_residuals(s, uk, dt, jac, res, R, J, reps):
    """The same by ``lanes.residual``, block by block, each taken from the robots' arrays first.

    Writes the results per robot into ``res`` (3, robots), ``R`` (robots, 2N), ``J`` (robots, 2N, width).
    """
    s = SimArrays(*s)
    n2, lanes_ = s.q.shape[1], lanes.LANES
    x = lanes.allocate(n2)
    p = np.empty((lanes.N_LANE_PRM, lanes_))
    out = np.empty((lanes.N_LANE_RES, lanes_))
    for _ in range(reps):
        for b in range(s.q.shape[0] // lanes_):
            lanes.take(s, uk, b * lanes_, x, p)
            lanes.residual(x, p, dt, jac, out)
            for r in range(lanes_):
                i = b * lanes_ + r
                res[0, i], res[1, i], res[2, i] = out[0, r], out[1, r], out[2, r]
    for b in range(s.q.shape[0] // lanes_):  # the last pass's R and J per robot, for the comparison
        lanes.take(s, uk, b * lanes_, x, p)
        lanes.residual(x, p, dt, jac, out)
        for r in range(lanes_):
            i = b * lanes_ + r
            for k in range(n2):
                R[i, k] = x.R[k * lanes_ + r]
                for c in range(J.shape[2]):
                    J[i, k, c] = x.J[(k * J.shape[2] + c) * lanes_ + r]


@njit(cache=True, error_model="numpy")
def block_solves(J0, b0, J, b, kept, reps):
    """``lanes.factor`` and ``lanes.solve`` on copies of flat blocks ``J0``, ``b0`` (blocks, flat)."""
    n = b0.shape[1] // lanes.LANES
    for _ in range(reps):
        J[:] = J0
        b[:] = b0
        for blk in range(J0.shape[0]):
            lanes.factor(J[blk], kept[blk], n)
            lanes.solve(J[blk], b[blk], n)


def to_lane_blocks(a: np.ndarray) -> np.ndarray:
    """(robots, ...) -> ``physics.lanes``' flat blocks (blocks, flat), element i of lane r at i LANES + r."""
    b = a.reshape((a.shape[0] // lanes.LANES, lanes.LANES, -1))
    return np.ascontiguousarray(b.transpose(0, 2, 1)).reshape(b.shape[0], -1)


def from_lane_blocks(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """The inverse of :func:`to_lane_blocks`, to ``shape`` (robots, ...)."""
    return a.reshape(a.shape[0], -1, lanes.LANES).transpose(0, 2, 1).reshape(shape)


@njit(cache=True, error_model="numpy")
def per_robot_solve(J0, b0, J, piv, b, reps):
    """``band_factor`` and ``band_solve`` robot by robot on copies of J0 (robots, n, width), b0."""
    n = J0.shape[1]
    for _ in range(reps):
        for r in range(J0.shape[0]):
            J[r] = J0[r]
            b[r] = b0[r]
            banded.band_factor(J[r], piv[r], n, PIVOT_THRESHOLD)
            banded.band_solve(J[r], piv[r], n, b[r])


@njit(cache=True, error_model="numpy")
def soa_solve(J0, b0, J, b, kept, reps):
    """The same with robots innermost (J0 (n, width, robots), b0 (n, robots)), no row exchanges.

    ``kept[r]`` is False where ``band_factor`` would exchange rows for robot r (or find it
    singular): that robot's result is not ``band_factor``'s and would be redone robot by robot.
    """
    n, _, R = J0.shape
    for _ in range(reps):
        J[:] = J0
        b[:] = b0
        kept[:] = True
        for k in range(n):
            imax = min(n, k + KL + 1)
            for r in range(R):  # band_factor's test: keep the diagonal if >= threshold x the largest below
                best = abs(J[k, KL, r])
                for i in range(k + 1, imax):
                    best = max(best, abs(J[i, k - i + KL, r]))
                kept[r] = kept[r] and abs(J[k, KL, r]) >= PIVOT_THRESHOLD * best and best > 0.0
            for i in range(k + 1, imax):
                for r in range(R):
                    J[i, k - i + KL, r] = J[i, k - i + KL, r] / J[k, KL, r]
                for j in range(k + 1, min(n - 1, k + KU) + 1):
                    for r in range(R):
                        J[i, j - i + KL, r] -= J[i, k - i + KL, r] * J[k, j - k + KL, r]
        for k in range(n):  # forward, then backward substitution, one row of b per loop
            for i in range(k + 1, min(n, k + KL + 1)):
                for r in range(R):
                    b[i, r] -= J[i, k - i + KL, r] * b[k, r]
        for k in range(n - 1, -1, -1):
            for j in range(k + 1, min(n - 1, k + KU) + 1):
                for r in range(R):
                    b[k, r] -= J[k, j - k + KL, r] * b[j, r]
            for r in range(R):
                b[k, r] = b[k, r] / J[k, KL, r]


def _timed(runs: dict, robots: int, rounds: int, reps: int) -> dict[str, float]:
    """Median thread CPU time per robot [ns] of each run, over interleaved rounds."""
    times: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            start = time.thread_time()
            run(reps)
            times[name].append((time.thread_time() - start) / (reps * robots) * 1e9)
    return {name: statistics.median(t) for name, t in times.items()}


def _print(title: str, same: bool, times: dict[str, float]) -> None:
    ref = next(iter(times.values()))
    print(f"{title}, bitwise equal: {same}")
    for name, t in times.items():
        print(f"  {name:<26} {t:7.0f} ns per robot  {ref / t:5.2f}x")


def probe(robots: int, rounds: int) -> bool:
    """Print the three variants' times for ``robots`` eels; False if their forces differ."""
    venv = gym.make_vec("SoftEel-v0", num_envs=robots, num_threads=1)
    venv.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(50):
        venv.step(rng.uniform(-1, 1, venv.action_space.shape))
    sim = venv.batch.sim
    q, v, kbar, lbar, prm, J = (np.array(a) for a in (sim.q, sim.v, sim.kbar, sim.lbar, sim.prm, sim.J))
    prm[:, layout.P_DSTRETCH] = 0.5  # stretching damping on too, so that every term is timed
    cols = [np.ascontiguousarray(a.T) for a in (q, v, kbar, lbar)]
    params = [
        np.ascontiguousarray(prm[:, i]) for i in (layout.P_EA, layout.P_EI, layout.P_DSTRETCH, layout.P_DBEND)
    ]
    F_ref, F_fused, F_split = np.zeros_like(q), np.zeros_like(cols[0]), np.zeros_like(cols[0])
    runs = {
        "per robot (assemble)": lambda n: per_robot(q, v, kbar, lbar, prm, F_ref, J, n),
        "fused": lambda n: fused(*cols, *params, F_fused, n),
        "split": lambda n: split(*cols, *params, F_split, n),
    }
    for run in runs.values():
        run(1)
    same = np.array_equal(F_ref, F_fused.T) and np.array_equal(F_ref, F_split.T)
    reps = max(1, 100_000 // robots)
    _print(f"{robots} eels, elastic and damping forces", same, _timed(runs, robots, rounds, reps))

    # the same forces and the water's drag, and the drag power
    P_ref, P_soa, prm_c = np.zeros(robots), np.zeros(robots), np.ascontiguousarray(prm.T)
    runs = {
        "per robot (assemble)": lambda k: per_robot_water(q, v, kbar, lbar, prm, F_ref, J, P_ref, k),
        "split": lambda k: split_water(*cols, *params, prm_c, F_split, P_soa, k),
    }
    for run in runs.values():
        run(1)
    water = np.array_equal(F_ref, F_split.T) and np.array_equal(P_ref, P_soa)
    _print(f"{robots} eels, forces with drag, and drag power", water, _timed(runs, robots, rounds, reps))

    # the same forces with their Jacobian (cx = -h^2, cv = -h as backward Euler's h = 0.01 s)
    cx, cv = -1e-4, -1e-2
    J_ref = np.zeros((robots, q.shape[1], J.shape[2]))
    J_soa = np.zeros((q.shape[1], J.shape[2], robots))
    scratch = np.zeros((N_SCRATCH, robots))
    runs = {
        "per robot (assemble)": lambda k: per_robot_jacobian(q, v, kbar, lbar, prm, F_ref, J_ref, cx, cv, k),
        "split": lambda k: split_jacobian(*cols, *params, F_split, J_soa, scratch, cx, cv, k),
    }
    blocked = {}  # width -> (forces, band) over blocks of that many robots
    for width in BLOCK_LANES:

        def to_blocks(a, width=width):  # (robots, ...) -> (blocks, ..., width)
            b = a.reshape((robots // width, width) + a.shape[1:])
            return np.ascontiguousarray(np.moveaxis(b, 1, -1))

        ins = [to_blocks(a) for a in (q, v, kbar, lbar)] + [to_blocks(p) for p in params]
        FB, JB = np.zeros_like(ins[0]), to_blocks(np.zeros_like(J_ref))
        TB = np.zeros((N_SCRATCH, width))
        blocked[width] = (FB, JB)
        runs[f"blocks of {width}"] = lambda k, ins=ins, FB=FB, JB=JB, TB=TB: blocked_jacobian(
            *ins, FB, JB, TB, cx, cv, k
        )
    for run in runs.values():
        run(1)
    jacobian = np.array_equal(F_ref, F_split.T) and np.array_equal(J_ref, J_soa.transpose(2, 0, 1))
    for FB, JB in blocked.values():
        jacobian &= np.array_equal(F_ref, np.moveaxis(FB, -1, 1).reshape(F_ref.shape))
        jacobian &= np.array_equal(J_ref, np.moveaxis(JB, -1, 1).reshape(J_ref.shape))
    _print(f"{robots} eels, forces and Jacobian", jacobian, _timed(runs, robots, rounds, reps))

    # backward Euler's whole residual in water, without and with its Jacobian, at each robot's
    # state (SDIRK2's stage of GAMMA h), robot by robot and by physics.lanes' blocks
    dt, residual = stepper.GAMMA * 0.01, True
    for jac in (False, True):
        res_ref, res_blk = np.zeros((3, robots)), np.zeros((3, robots))
        R_blk, J_blk = np.zeros(q.shape), np.zeros((robots, q.shape[1], J.shape[2]))
        runs = {
            "per robot (_be_residual)": lambda k, jac=jac, res=res_ref: per_robot_residual(
                tuple(sim), dt, jac, res, k
            ),
            f"blocks of {LANES} (lanes)": lambda k, jac=jac, res=res_blk, R=R_blk, J=J_blk: block_residuals(
                tuple(sim), venv.batch.task.uk, dt, jac, res, R, J, k
            ),
        }
        for run in runs.values():
            run(1)
        same = np.array_equal(res_ref, res_blk) and np.array_equal(sim.buf[:, layout.B_R], R_blk)
        if jac:
            same &= np.array_equal(sim.J, J_blk)
        title = f"{robots} eels, backward Euler's residual in water" + (" and its Jacobian" if jac else "")
        _print(title, same, _timed(runs, robots, rounds, reps))
        residual &= same

    # the backward-Euler Jacobian of each robot's state (water, h = 0.01 s), factored and solved
    n = q.shape[1]
    J0 = np.zeros((robots, n, J.shape[2]))
    for r in range(robots):
        arrays = layout.SimArrays(*(np.array(a[r]) for a in sim))
        stepper._be_residual(arrays, 0.01, layout.MEDIUM_WATER, True)
        J0[r] = arrays.J
    b0 = rng.standard_normal((robots, n))
    Jw, bw, piv = np.empty_like(J0), np.empty_like(b0), np.zeros((robots, n), dtype=np.int64)
    J0c, b0c = np.ascontiguousarray(J0.transpose(1, 2, 0)), np.ascontiguousarray(b0.T)
    Jc, bc, kept = np.empty_like(J0c), np.empty_like(b0c), np.ones(robots, dtype=np.bool_)
    J0f, b0f = to_lane_blocks(J0), to_lane_blocks(b0)
    Jf, bf, keptf = np.empty_like(J0f), np.empty_like(b0f), np.ones((robots // LANES, LANES), np.bool_)
    runs = {
        "per robot (band_factor)": lambda k: per_robot_solve(J0, b0, Jw, piv, bw, k),
        "robots innermost": lambda k: soa_solve(J0c, b0c, Jc, bc, kept, k),
        f"blocks of {LANES} (lanes)": lambda k: block_solves(J0f, b0f, Jf, bf, keptf, k),
    }
    for run in runs.values():
        run(1)
    exchanged = int((piv != np.arange(n)).any(axis=1).sum())
    solved = bool(kept.all()) and np.array_equal(bw, bc.T) and np.array_equal(Jw, Jc.transpose(2, 0, 1))
    solved &= bool(keptf.all()) and np.array_equal(bw, from_lane_blocks(bf, bw.shape))
    solved &= np.array_equal(Jw, from_lane_blocks(Jf, Jw.shape))
    title = f"{robots} eels, factor + solve (2N = {n}; robots with a row exchange: {exchanged})"
    _print(title, solved, _timed(runs, robots, rounds, reps))
    return same and water and jacobian and residual and solved


def main() -> int:
    """Probe each robot count; exit 1 if any variant's forces differ from ``assemble``'s."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[32, 256])
    parser.add_argument("--rounds", type=int, default=11, help="interleaved rounds (medians)")
    args = parser.parse_args()
    ok = [probe(n, args.rounds) for n in args.robots]
    return 0 if all(ok) else 1


if __name__ == "__main__":
    sys.exit(main())
