"""Banded LU for the (2N x 2N) Newton and mass matrices, with row exchanges only where needed.

Storage (LAPACK ``gbtrf`` layout, row-major): ``A[i, j]`` lives at ``J[i, j - i + KL]``.
Each row keeps ``2 KL + KU + 1`` slots so that pivoting's fill-in fits. With interleaved
(x, y) ordering the bending stencil couples nodes two apart, so ``KL = KU = 5``.

:func:`band_factor` is LU with threshold pivoting: a column keeps its diagonal pivot when it is
at least ``PIVOT_THRESHOLD`` times the column's largest entry below it, and only otherwise takes
the row of that entry (partial pivoting). The backward-Euler matrix (mass, added mass, the
elastic Hessian, the drag Jacobian, all scaled by the step) has a dominant diagonal, so in
practice no row moves and the factors keep the band's upper width ``KU``: half the work of
:func:`band_lu`, whose partial pivoting fills the upper band to ``KL + KU``. Where a row must
move (a matrix that is far from diagonally dominant) it falls back to the exchange and the
fill-in, and the growth of the factors stays bounded by ``1 + 1/PIVOT_THRESHOLD`` per step.
(The matrix is not symmetric: the drag's and the damping's position derivatives, the water's
gyroscopic terms and the stuck contacts' rows make it not, so a Cholesky or LDL^T factorization
of it would be a different, inexact Newton; see docs/performance.md.)
Cost is O(n KL KU) without exchanges, O(n KL (KL + KU)) with: linear in N.

The factors keep each pivot's reciprocal on the diagonal: one division a column, and the
solve's back substitution, a chain through the rows, multiplies where it divided (a division
takes about three times as long as a multiplication to give its result).
"""

from __future__ import annotations

import numpy as np
from numba import njit

KL = 5
KU = 5
WIDTH = 2 * KL + KU + 1
PIVOT_THRESHOLD = 0.1
"""A diagonal pivot at least this fraction of its column's largest entry is kept (no row exchange)."""


@njit(cache=True, inline="always", error_model="numpy")
def _factor(J, piv, n, threshold):
    """LU of the band in ``J`` in place, exchanging rows where the diagonal is below ``threshold`` of its column's largest entry."""
    reach = 0  # the last column a row exchange has filled in
    for k in range(n):
        if reach <= k + KU and k + KL < n and k + KU < n:
            # the band is whole and no exchange reaches past it: the pivot's test as a maximum
            # without branches (the same one as the search's below, which then picks the row),
            # and KL rows of KU entries each, loops of constant length that the compiler unrolls
            # (the same operations in the same order)
            diag = abs(J[k, KL])
            best = diag
            for d in range(1, KL + 1):
                best = max(best, abs(J[k + d, KL - d]))
            if diag >= threshold * best and best > 0.0:
                piv[k] = k
                inv = 1.0 / J[k, KL]
                J[k, KL] = inv
                for d in range(1, KL + 1):
                    f = J[k + d, KL - d] * inv
                    J[k + d, KL - d] = f
                    if f != 0.0:
                        for e in range(1, KU + 1):
                            J[k + d, KL - d + e] -= f * J[k, KL + e]
                continue
        diag = abs(J[k, KL])
        p = k
        best = diag
        imax = min(n, k + KL + 1)
        for i in range(k + 1, imax):
            val = abs(J[i, k - i + KL])
            if val > best:
                best = val
                p = i
        if diag >= threshold * best:
            p = k
            best = diag
        piv[k] = p
        if best == 0.0:
            return False
        if p != k:
            reach = max(reach, p + KU)
        jmax = min(n - 1, max(k + KU, reach))
        if p != k:
            for j in range(k, jmax + 1):
                tmp = J[k, j - k + KL]
                J[k, j - k + KL] = J[p, j - p + KL]
                J[p, j - p + KL] = tmp
        inv = 1.0 / J[k, KL]
        J[k, KL] = inv
        for i in range(k + 1, imax):
            f = J[i, k - i + KL] * inv
            J[i, k - i + KL] = f
            if f != 0.0:
                for j in range(k + 1, jmax + 1):
                    J[i, j - i + KL] -= f * J[k, j - k + KL]
    return True


@njit(cache=True, error_model="numpy", _nrt=False)
def band_factor(J: np.ndarray, piv: np.ndarray, n: int, threshold: float) -> bool:
    """Factor the band matrix in ``J`` in place with threshold pivoting; returns False if it is singular.

    A diagonal pivot at least ``threshold`` times its column's largest entry below it is kept
    (``PIVOT_THRESHOLD``, or 1.0 for partial pivoting). ``piv[k]`` is the row exchanged with
    row k (k itself: none). Solve with :func:`band_solve`.
    """
    return _factor(J, piv, n, threshold)


@njit(cache=True, error_model="numpy", _nrt=False)
def band_lu(J: np.ndarray, piv: np.ndarray, n: int) -> bool:
    """Factor the band matrix in ``J`` in place with partial pivoting; returns False if it is singular."""
    return _factor(J, piv, n, 1.0)


@njit(cache=True, error_model="numpy", _nrt=False)
def band_solve(J: np.ndarray, piv: np.ndarray, n: int, b: np.ndarray) -> None:
    """Solve ``A x = b`` in place in ``b`` with the factors of :func:`band_factor` or :func:`band_lu`."""
    reach = 0
    for k in range(n):
        p = piv[k]
        if p != k:
            reach = max(reach, p + KU)
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
        # every row, a 0 too (it changes no entry but the sign of a 0): a skip of 0 entries
        # is a branch per lane in lanes.solve, which keeps that loop scalar on AMD's Zen 3
        bk = b[k]
        if k + KL < n:  # constant-length loops where the band is whole (as in band_factor)
            for d in range(1, KL + 1):
                b[k + d] -= J[k + d, KL - d] * bk
        else:
            for i in range(k + 1, n):
                b[i] -= J[i, k - i + KL] * bk
    for k in range(n - 1, -1, -1):
        s = b[k]
        if reach <= k + KU and k + KU < n:
            for e in range(1, KU + 1):
                s -= J[k, KL + e] * b[k + e]
        else:
            # row k of U reaches at most k + KL + KU, and without exchanges k + KU
            for j in range(k + 1, min(n - 1, k + KL + KU, max(k + KU, reach)) + 1):
                s -= J[k, j - k + KL] * b[j]
        b[k] = s * J[k, KL]  # the factors hold the pivot's reciprocal


@njit(cache=True, inline="always", error_model="numpy")
def add_block(J, i, j, m00, m01, m10, m11):
    """Add a 2x2 block to the band at node pair (i, j)."""
    r = 2 * i
    c = 2 * j - r + KL
    J[r, c] += m00
    J[r, c + 1] += m01
    J[r + 1, c - 1] += m10
    J[r + 1, c] += m11


@njit(cache=True, inline="always", error_model="numpy")
def add_edge_pattern(J, k, s00, s01, s11):
    """Add the pattern [[-S, S], [S, -S]] of a symmetric 2x2 S to nodes (k, k+1)."""
    add_block(J, k, k, -s00, -s01, -s01, -s11)
    add_block(J, k, k + 1, s00, s01, s01, s11)
    add_block(J, k + 1, k, s00, s01, s01, s11)
    add_block(J, k + 1, k + 1, -s00, -s01, -s01, -s11)


def band_to_dense(J: np.ndarray, n: int) -> np.ndarray:
    """The dense (n, n) matrix of an unfactored band (for tests and debugging)."""
    A = np.zeros((n, n))
    for i in range(n):
        for j in range(max(0, i - KL), min(n, i + KL + KU + 1)):
            A[i, j] = J[i, j - i + KL]
    return A
