"""Tests of the banded linear algebra behind factorize_spd."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from corl.trajectory.solver.banded import BandedCholeskyFactor, BandedSPD, SupportGram, banded_cholesky
from corl.trajectory.solver.linalg import SparseLUFactor, factorize_spd


def banded_spd(n=60, u=5, seed=0):
    rng = np.random.default_rng(seed)
    J = sp.lil_matrix((3 * n, n))
    for i in range(3 * n):  # each row touches u + 1 consecutive columns: J^T J has bandwidth u
        start = rng.integers(0, n - u)
        J[i, start : start + u + 1] = rng.normal(size=u + 1)
    J = J.tocsr()
    return (J.T @ J + 0.1 * sp.identity(n)).tocsr()


def test_banded_cholesky_solve_equals_dense_solve():
    H = banded_spd()
    b = np.random.default_rng(1).normal(size=H.shape[0])
    band = BandedSPD.from_sparse(H)
    assert band.bandwidth == 5
    x = banded_cholesky(band.ab, 0.3).solve(b)
    np.testing.assert_allclose(x, np.linalg.solve(H.toarray() + 0.3 * np.eye(60), b), rtol=1e-10)
    np.testing.assert_allclose(band @ b, H @ b, rtol=1e-12)
    np.testing.assert_allclose(band.toarray(), H.toarray(), rtol=1e-14)


def test_factorize_spd_picks_the_band_for_sparse_input_even_when_shuffled():
    H = banded_spd(n=200, u=4, seed=2)
    b = np.random.default_rng(3).normal(size=200)
    factor = factorize_spd(H, 1e-3)
    assert isinstance(factor, BandedCholeskyFactor) and factor.perm is None
    perm = np.random.default_rng(4).permutation(200)
    shuffled = H[perm][:, perm]
    factor = factorize_spd(shuffled, 1e-3)  # reverse Cuthill-McKee restores a narrow band
    assert isinstance(factor, BandedCholeskyFactor) and factor.perm is not None
    dense = shuffled.toarray() + 1e-3 * np.eye(200)
    np.testing.assert_allclose(factor.solve(b[perm]), np.linalg.solve(dense, b[perm]), rtol=1e-9)


def test_factorize_spd_falls_back_to_superlu_for_a_wide_band():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(40, 40))
    H = sp.csr_matrix(A @ A.T + np.eye(40))
    assert isinstance(factorize_spd(H), SparseLUFactor)


def test_support_gram_adds_like_dense_and_widens_the_band():
    H = banded_spd(n=50, u=3, seed=6)
    J = sp.csr_matrix(np.vstack([np.r_[np.zeros(10), np.ones(4), np.zeros(36)], np.r_[np.zeros(44), np.arange(1.0, 7.0)]]))
    G = SupportGram.from_jacobian(J, 2.0)
    total = BandedSPD.from_sparse(H) + 3.0 * G
    np.testing.assert_allclose(total.toarray(), H.toarray() + 6.0 * (J.T @ J).toarray(), atol=1e-12)
    assert total.bandwidth == 5  # the second row spans 6 columns; no start-end coupling is stored


def test_banded_sum_adds_its_blocks_like_dense_and_a_covered_block_merges():
    from corl.trajectory.solver.banded import BandedSum, SupportPattern

    H = banded_spd(n=50, u=3, seed=7)
    base = BandedSPD.from_sparse(H)
    support = np.array([0, 1, 20, 21, 22, 23])
    touched = np.array([[1, 0, 0, 0, 0, 0], [0, 1, 0, 0, 0, 0], [0, 0, 1, 1, 1, 1]], dtype=bool)
    pattern = SupportPattern(support, touched)
    rng = np.random.default_rng(8)
    Js = np.where(touched, rng.normal(size=touched.shape), 0.0)
    gram = SupportGram(support, 2.0 * Js.T @ Js, 50, pattern.pairs, Js, pattern)
    curvature = SupportGram.dense_block(np.arange(20, 24), np.full((4, 4), 0.5), 50)
    total = BandedSum(base, (gram, curvature))
    dense = H.toarray() + gram.toarray() + curvature.toarray()
    assert total.bandwidth == 3
    np.testing.assert_allclose(BandedSPD(total.band()).toarray(), dense, atol=1e-13 * np.abs(dense).max())
    x = rng.normal(size=50)
    np.testing.assert_allclose(total @ x, dense @ x, rtol=1e-12)
    np.testing.assert_allclose(total.diagonal(), np.diagonal(dense), rtol=1e-12)
    at = gram.covers(curvature)  # the contact row touches all four columns: the block merges
    np.testing.assert_array_equal(at, [2, 3, 4, 5])
    assert gram.covers(SupportGram.dense_block(np.array([1, 20]), np.eye(2), 50)) is None  # 1 and 20: no row
