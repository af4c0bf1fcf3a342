"""Banded LU with partial pivoting for the (2N x 2N) Newton and mass matrices.

Storage (LAPACK ``gbtrf`` layout, row-major): ``A[i, j]`` lives at ``J[i, j - i + KL]``.
Each row keeps ``2 KL + KU + 1`` slots so that pivoting's fill-in fits. With interleaved
(x, y) ordering the bending stencil couples nodes two apart, so ``KL = KU = 5``.
Cost is O(n KL (KL + KU)): linear in N.
"""

from __future__ import annotations

import numpy as np
from numba import njit

KL = 5
KU = 5
WIDTH = 2 * KL + KU + 1


@njit(cache=True, error_model="numpy")
def band_lu(J: np.ndarray, piv: np.ndarray, n: int) -> bool:
    """Factor the band matrix in ``J`` in place; returns False if it is singular."""
    for k in range(n):
        p = k
        best = abs(J[k, KL])
        imax = min(n, k + KL + 1)
        for i in range(k + 1, imax):
            val = abs(J[i, k - i + KL])
            if val > best:
                best = val
                p = i
        piv[k] = p
        if best == 0.0:
            return False
        jmax = min(n - 1, k + KL + KU)
        if p != k:
            for j in range(k, jmax + 1):
                tmp = J[k, j - k + KL]
                J[k, j - k + KL] = J[p, j - p + KL]
                J[p, j - p + KL] = tmp
        pivot = J[k, KL]
        for i in range(k + 1, imax):
            f = J[i, k - i + KL] / pivot
            J[i, k - i + KL] = f
            if f != 0.0:
                for j in range(k + 1, jmax + 1):
                    J[i, j - i + KL] -= f * J[k, j - k + KL]
    return True


@njit(cache=True, error_model="numpy")
def band_solve(J: np.ndarray, piv: np.ndarray, n: int, b: np.ndarray) -> None:
    """Solve ``A x = b`` in place in ``b`` with the factors from :func:`band_lu`."""
    for k in range(n):
        p = piv[k]
        if p != k:
            tmp = b[k]
            b[k] = b[p]
            b[p] = tmp
        bk = b[k]
        if bk != 0.0:
            for i in range(k + 1, min(n, k + KL + 1)):
                b[i] -= J[i, k - i + KL] * bk
    for k in range(n - 1, -1, -1):
        s = b[k]
        for j in range(k + 1, min(n, k + KL + KU + 1)):
            s -= J[k, j - k + KL] * b[j]
        b[k] = s / J[k, KL]


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
