"""The banded factorizations against numpy/scipy: threshold pivoting, its fallback, partial pivoting."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import solve_banded

from soft_snake_gym.physics.banded import (
    KL,
    KU,
    PIVOT_THRESHOLD,
    WIDTH,
    band_factor,
    band_lu,
    band_solve,
    band_to_dense,
)


def _band_of(A: np.ndarray) -> np.ndarray:
    """The (n, WIDTH) storage of a dense matrix with lower/upper bandwidths KL, KU."""
    n = A.shape[0]
    J = np.zeros((n, WIDTH))
    for i in range(n):
        for j in range(max(0, i - KL), min(n, i + KU + 1)):
            J[i, j - i + KL] = A[i, j]
    return J


def _random_band(rng, n: int) -> np.ndarray:
    A = rng.standard_normal((n, n))
    i, j = np.indices((n, n))
    A[(j - i > KU) | (i - j > KL)] = 0.0
    return A


def _random_spd_band(rng, n: int) -> np.ndarray:
    """B B^T + diag with B of lower bandwidth 2 (so the product has bandwidth 4 <= KL)."""
    B = np.tril(rng.standard_normal((n, n)))
    i, j = np.indices((n, n))
    B[i - j > 2] = 0.0
    return B @ B.T + 0.1 * np.eye(n)


def _threshold(J, piv, n):
    return band_factor(J, piv, n, PIVOT_THRESHOLD)


def _solve(factor, A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    n = A.shape[0]
    J = _band_of(A)
    piv = np.zeros(n, dtype=np.int64)
    ok = factor(J, piv, n)
    x = b.copy()
    if ok:
        band_solve(J, piv, n, x)
    return x, piv, ok


@pytest.mark.parametrize("n", [1, 2, 7, 20, 60])
def test_threshold_lu_on_spd_bands_needs_no_exchange_and_matches_scipy(n):
    rng = np.random.default_rng(n)
    for _ in range(20):
        A = _random_spd_band(rng, n)
        b = rng.standard_normal(n)
        x, piv, ok = _solve(_threshold, A, b)
        assert ok
        assert np.array_equal(piv, np.arange(n))  # SPD: every diagonal pivot is kept
        ab = np.zeros((2 * KL + 1, n))  # scipy's (l + u + 1, n) diagonal-ordered form
        for i in range(n):
            for j in range(max(0, i - KL), min(n, i + KL + 1)):
                ab[KL + i - j, j] = A[i, j]
        ref = solve_banded((KL, KL), ab, b)
        assert np.allclose(x, ref, rtol=1e-10, atol=1e-12)
        assert np.allclose(A @ x, b, atol=1e-10 * np.abs(b).max())


def test_threshold_lu_falls_back_to_row_exchanges_where_the_diagonal_is_small():
    rng = np.random.default_rng(1)
    exchanged = 0
    for _ in range(200):
        n = 20
        A = _random_band(rng, n)
        A[np.arange(n), np.arange(n)] *= 1e-3  # small diagonal: most columns need a row exchange
        b = rng.standard_normal(n)
        x, piv, ok = _solve(_threshold, A, b)
        assert ok
        exchanged += int((piv != np.arange(n)).sum())
        assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-8, atol=1e-8)
    assert exchanged > 200  # the fallback ran, on average more than once per matrix


def test_a_pivot_just_above_the_threshold_is_kept_and_just_below_is_exchanged():
    for scale, exchange in ((1.001, False), (0.999, True)):
        A = np.array([[PIVOT_THRESHOLD * scale, 1.0, 0.0], [1.0, 1.0, 1.0], [0.0, 1.0, 3.0]])
        b = np.array([1.0, 2.0, 3.0])
        x, piv, ok = _solve(_threshold, A, b)
        assert ok and (piv[0] == 1) == exchange
        assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-10)


def test_partial_pivoting_lu_matches_numpy_and_exchanges_for_the_largest_entry():
    rng = np.random.default_rng(2)
    for _ in range(100):
        A = _random_band(rng, 16)
        b = rng.standard_normal(16)
        x, piv, ok = _solve(band_lu, A, b)
        assert ok
        assert np.allclose(x, np.linalg.solve(A, b), rtol=1e-8, atol=1e-8)
    A = np.array([[1.0, 2.0], [3.0, 4.0]])
    _, piv, _ = _solve(band_lu, A, np.ones(2))
    assert piv[0] == 1  # |3| > |1|: partial pivoting exchanges where the threshold one would not
    _, piv, _ = _solve(_threshold, A, np.ones(2))
    assert piv[0] == 0


def test_singular_band_is_reported():
    A = np.zeros((4, 4))
    A[0, 0] = 1.0
    for factor in (_threshold, band_lu):
        assert not _solve(factor, A, np.ones(4))[2]


def test_band_storage_round_trip():
    rng = np.random.default_rng(3)
    A = _random_band(rng, 12)
    assert np.array_equal(band_to_dense(_band_of(A), 12), A)


def _reference_factor(J, piv, n, threshold):
    """The threshold LU in plain Python with one general loop per column (no constant-length path)."""
    reach = 0
    for k in range(n):
        diag = abs(J[k, KL])
        p, best = k, diag
        imax = min(n, k + KL + 1)
        for i in range(k + 1, imax):
            if abs(J[i, k - i + KL]) > best:
                best, p = abs(J[i, k - i + KL]), i
        if diag >= threshold * best:
            p, best = k, diag
        piv[k] = p
        if p != k:
            reach = max(reach, p + KU)
        jmax = min(n - 1, max(k + KU, reach))
        if p != k:
            for j in range(k, jmax + 1):
                J[k, j - k + KL], J[p, j - p + KL] = J[p, j - p + KL], J[k, j - k + KL]
        J[k, KL] = 1.0 / J[k, KL]  # the factors hold the pivot's reciprocal
        for i in range(k + 1, imax):
            f = J[i, k - i + KL] * J[k, KL]
            J[i, k - i + KL] = f
            if f != 0.0:
                for j in range(k + 1, jmax + 1):
                    J[i, j - i + KL] -= f * J[k, j - k + KL]


def _reference_solve(J, piv, n, b):
    reach = 0
    for k in range(n):
        if piv[k] != k:
            reach = max(reach, piv[k] + KU)
            b[k], b[piv[k]] = b[piv[k]], b[k]
        if b[k] != 0.0:
            for i in range(k + 1, min(n, k + KL + 1)):
                b[i] -= J[i, k - i + KL] * b[k]
    for k in range(n - 1, -1, -1):
        s = b[k]
        for j in range(k + 1, min(n - 1, k + KL + KU, max(k + KU, reach)) + 1):
            s -= J[k, j - k + KL] * b[j]
        b[k] = s * J[k, KL]


@pytest.mark.parametrize("n", [4, 11, 20, 40])
def test_the_constant_length_loops_are_bit_for_bit_the_general_ones(n):
    # where no exchange reaches past a column, band_factor and band_solve run loops of constant
    # length; they must do the general loops' operations in the same order, or every trajectory's
    # digits would change. Half of these bands exchange rows (small diagonals), half do not.
    rng = np.random.default_rng(n)
    exchanged = 0
    for trial in range(40):
        A = _random_band(rng, n)
        if trial % 2:
            A += np.diag(np.full(n, 8.0))
        J, J_ref = _band_of(A), _band_of(A)
        piv, piv_ref = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        assert band_factor(J, piv, n, PIVOT_THRESHOLD)
        _reference_factor(J_ref, piv_ref, n, PIVOT_THRESHOLD)
        assert np.array_equal(piv, piv_ref) and np.array_equal(J, J_ref)
        exchanged += bool((piv != np.arange(n)).any())
        b = rng.standard_normal(n)
        x, x_ref = b.copy(), b.copy()
        band_solve(J, piv, n, x)
        _reference_solve(J_ref, piv_ref, n, x_ref)
        assert np.array_equal(x, x_ref)
    assert 0 < exchanged < 40  # both paths were taken


@pytest.mark.parametrize("below", ["random", "zeros", "tie", "inf", "nan"])
def test_the_pivot_test_as_a_maximum_decides_as_the_search_does(below):
    # where the band is whole, band_factor tests the diagonal against the largest entry below it
    # with a branch-free maximum and searches for the row only if the test fails; at the test's
    # edge (exactly the threshold, one ulp either side), with ties, zeros, an infinity or a NaN
    # below the diagonal, it must keep or exchange exactly as the search would
    rng = np.random.default_rng(7)
    n = 12
    column = {
        "random": rng.standard_normal(KL),
        "zeros": np.zeros(KL),
        "tie": np.array([2.0, -3.0, 3.0, 1.0, -3.0]),
        "inf": np.array([1.0, np.inf, 2.0, 0.0, 1.0]),
        "nan": np.array([1.0, np.nan, 2.0, 0.0, 4.0]),
    }[below]
    largest = np.nanmax(np.abs(column))
    edge = PIVOT_THRESHOLD * largest if largest > 0 else 1.0
    for diagonal in (edge, np.nextafter(edge, 0.0), np.nextafter(edge, np.inf), 0.0, -edge):
        A = _random_band(rng, n) + np.diag(np.full(n, 8.0))
        A[0, 0] = diagonal
        A[1 : KL + 1, 0] = column
        J, J_ref = _band_of(A), _band_of(A)
        piv, piv_ref = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        with np.errstate(invalid="ignore", divide="ignore"):
            ok = band_factor(J, piv, n, PIVOT_THRESHOLD)
            _reference_factor(J_ref, piv_ref, n, PIVOT_THRESHOLD)
        assert ok == (diagonal != 0.0 or largest > 0)  # (the reference goes on past a zero column)
        if ok:
            assert J.tobytes() == J_ref.tobytes() and np.array_equal(piv, piv_ref), diagonal
