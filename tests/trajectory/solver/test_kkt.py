"""Tests of the banded KKT steps of the SQP solver (corl.trajectory.solver.kkt) against dense linear algebra."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.linalg import null_space

from corl.trajectory.solver.banded import BandedSPD
from corl.trajectory.solver.kkt import (
    IndefiniteHessian,
    KKTSystem,
    StepFailure,
    Unreachable,
    constrained_step,
)

N = 40


def banded_hessian(seed: int, shift: float = 0.0) -> tuple[BandedSPD, np.ndarray]:
    """A second-difference cost's Hessian (bandwidth 2, singular: linear motions cost nothing) + shift I."""
    D = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(N - 2, N)).toarray()
    rng = np.random.default_rng(seed)
    H = 2.0 * D.T @ np.diag(rng.uniform(0.5, 2.0, N - 2)) @ D + shift * np.eye(N)
    return BandedSPD.from_sparse(sp.csr_matrix(H)), H


def constraint_rows(seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Start, end and one interior row (they pin the linear motions): (support, Js, dense Jh (3, N))."""
    rng = np.random.default_rng(seed)
    support = np.array([0, 1, 17, 18, 19, 38, 39])
    Js = np.zeros((3, support.shape[0]))
    Js[0, :2] = rng.normal(size=2)
    Js[1, 2:5] = rng.normal(size=3)
    Js[2, 5:] = rng.normal(size=2)
    Jh = np.zeros((3, N))
    Jh[:, support] = Js
    return support, Js, Jh


def dense_kkt(H, Jh, g, h, nu=0.0, u=None):
    """Solve [[H + nu I, Jh^T], [Jh, 0]] [d; lam] = [-(g + nu u); -h] densely."""
    q = Jh.shape[0]
    K = np.block([[H + nu * np.eye(N), Jh.T], [Jh, np.zeros((q, q))]])
    rhs = np.concatenate([-(g + (nu * u if u is not None else 0.0)), -h])
    sol = np.linalg.solve(K, rhs)
    return sol[:N], sol[N:]


def test_kkt_system_solves_the_dense_kkt_equations():
    Hb, H = banded_hessian(0)
    support, Js, Jh = constraint_rows(1)
    rng = np.random.default_rng(2)
    b, c = rng.normal(size=N), rng.normal(size=3)
    # H alone is singular (linear motions), H + Jh^T Jh is not: the KKT matrix is regular.
    Hb_aug = (1.0 * BandedSPD.from_sparse(sp.csr_matrix(Jh.T @ Jh))) + Hb
    a, lam = KKTSystem(Hb_aug, 0.3, support, Js).solve(b, c)
    d_ref, lam_ref = dense_kkt(H + Jh.T @ Jh, Jh, b, c, nu=0.3, u=np.zeros(N))
    np.testing.assert_allclose(a, d_ref, rtol=1e-9, atol=1e-10 * np.abs(d_ref).max())
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-9, atol=1e-10 * np.abs(lam_ref).max())


def test_step_without_ball_is_the_equality_constrained_newton_step():
    Hb, H = banded_hessian(3, shift=0.1)
    support, Js, Jh = constraint_rows(4)
    rng = np.random.default_rng(5)
    g, h = rng.normal(size=N), 0.1 * rng.normal(size=3)
    d, lam, z, nu = constrained_step(Hb, g, support, Js, h)
    d_ref, lam_ref = dense_kkt(H, Jh, g, h)
    assert z is None and nu == 0.0
    np.testing.assert_allclose(d, d_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-9, atol=1e-12)


def _assert_ball_step_is_optimal(H, Jh, g, h, u, radius, d, lam, z, nu):
    """KKT of min g^T d + d^T H d / 2 s.t. Jh d = -h, ||u + d|| <= radius, with the ball active, and the
    second-order condition Z^T (H + nu I) Z > 0 that makes it the global minimizer (More & Sorensen)."""
    assert z is not None and nu > 0.0
    np.testing.assert_allclose(z, u + d, atol=1e-14)
    assert np.linalg.norm(z) == pytest.approx(radius, rel=1e-10)
    np.testing.assert_allclose(Jh @ d, -h, atol=1e-10 * (np.abs(h).max() + np.abs(Jh).max() * np.abs(d).max()))
    residual = (H + nu * np.eye(N)) @ d + Jh.T @ lam + g + nu * u
    np.testing.assert_allclose(residual, 0.0, atol=1e-8 * (1 + np.abs(g).max()))
    Z = null_space(Jh)
    assert np.linalg.eigvalsh(Z.T @ (H + nu * np.eye(N)) @ Z)[0] > 0.0


def _ball_case():
    """A trust-region subproblem whose ball is active: (Hb, H, support, Js, Jh, g, h, u, radius)."""
    Hb, H = banded_hessian(6, shift=0.05)
    support, Js, Jh = constraint_rows(7)
    rng = np.random.default_rng(8)
    g, h = 10.0 * rng.normal(size=N), 0.01 * rng.normal(size=3)
    u = rng.normal(size=N)
    radius = 1.5 * np.linalg.norm(u)
    return Hb, H, support, Js, Jh, g, h, u, radius


def test_ball_step_solves_the_trust_region_subproblem():
    Hb, H, support, Js, Jh, g, h, u, radius = _ball_case()
    d, lam, z, nu = constrained_step(Hb, g, support, Js, h, u, radius)
    _assert_ball_step_is_optimal(H, Jh, g, h, u, radius, d, lam, z, nu)
    # A warm start from a nearby multiplier gives the same step.
    d2, lam2, _, nu2 = constrained_step(Hb, g, support, Js, h, u, radius, nu_guess=3.0 * nu)
    assert nu2 == pytest.approx(nu, rel=1e-8)
    np.testing.assert_allclose(d2, d, atol=1e-10 * np.abs(d).max())


def test_ball_step_with_an_indefinite_hessian_uses_a_definite_shift():
    Hb, H = banded_hessian(9, shift=0.0)
    support, Js, Jh = constraint_rows(10)
    # Negative curvature on a block (as the constraint curvature lam^T d2h adds to the Hessian).
    C = np.zeros((N, N))
    C[20:24, 20:24] = -3.0 * np.eye(4)
    H = H + C
    Hb = BandedSPD.from_sparse(sp.csr_matrix(H), 2)
    assert np.linalg.eigvalsh(H)[0] < 0
    rng = np.random.default_rng(11)
    g, h, u = rng.normal(size=N), np.zeros(3), np.zeros(N)
    with pytest.raises(IndefiniteHessian):
        constrained_step(Hb, g, support, Js, h)  # no ball: no step
    d, lam, z, nu = constrained_step(Hb, g, support, Js, h, u, 0.5, nu_definite=3.0 + 1e-6)
    _assert_ball_step_is_optimal(H, Jh, g, h, u, 0.5, d, lam, z, nu)
    assert np.linalg.eigvalsh(H + nu * np.eye(N))[0] > 0.0


def test_the_definite_shift_is_computed_only_when_the_first_shifts_fail():
    Hb, H = banded_hessian(9, shift=0.05)  # definite: no shift needed
    support, Js, Jh = constraint_rows(10)
    rng = np.random.default_rng(11)
    g, h, u = rng.normal(size=N), np.zeros(3), np.zeros(N)
    calls = []

    def shift():
        calls.append(1)
        return 3.0

    d, lam, z, nu = constrained_step(Hb, g, support, Js, h, u, 0.5, nu_definite=shift)
    assert calls == []
    _assert_ball_step_is_optimal(H, Jh, g, h, u, 0.5, d, lam, z, nu)
    C = np.zeros((N, N))
    C[20:24, 20:24] = -3.0 * np.eye(4)
    indefinite = BandedSPD.from_sparse(sp.csr_matrix(H + C), 2)
    d, lam, z, nu = constrained_step(indefinite, g, support, Js, h, u, 0.5, nu_definite=lambda: 3.0 + 1e-6)
    _assert_ball_step_is_optimal(H + C, Jh, g, h, u, 0.5, d, lam, z, nu)


def test_ball_iteration_stops_when_rounding_keeps_it_off_the_tolerance(monkeypatch):
    """With a tolerance no floating-point step can meet, the Newton iteration on the ball multiplier
    stops once it no longer gets closer (a few steps), not after _SECULAR_MAX_ITER factorizations,
    and returns the closest step it found, on the ball to rounding."""
    import corl.trajectory.solver.kkt as kkt

    Hb, H, support, Js, Jh, g, h, u, radius = _ball_case()
    reference = constrained_step(Hb, g, support, Js, h, u, radius)
    monkeypatch.setattr(kkt, "_SECULAR_TOL", 0.0)
    built = []
    original = kkt.KKTSystem.__init__

    def counting(self, *args, **kwargs):
        built.append(1)
        original(self, *args, **kwargs)

    monkeypatch.setattr(kkt.KKTSystem, "__init__", counting)
    d, lam, z, nu = constrained_step(Hb, g, support, Js, h, u, radius)
    assert len(built) < kkt._SECULAR_MAX_ITER // 2
    _assert_ball_step_is_optimal(H, Jh, g, h, u, radius, d, lam, z, nu)
    np.testing.assert_allclose(d, reference[0], atol=1e-10 * np.linalg.norm(reference[0]))


def test_linearized_constraints_out_of_the_ball_raise_unreachable():
    Hb, _ = banded_hessian(12, shift=0.1)
    support, Js, _ = constraint_rows(13)
    h = np.array([5.0, -5.0, 5.0])
    rng = np.random.default_rng(14)
    with pytest.raises(Unreachable, match="radius"):
        constrained_step(Hb, rng.normal(size=N), support, Js, h, np.zeros(N), 0.01)


def test_dependent_constraint_rows_raise_step_failure():
    Hb, _ = banded_hessian(15, shift=0.1)
    support, Js, _ = constraint_rows(16)
    Js = np.vstack([Js, Js[1]])  # a duplicated row: the Schur complement is singular
    with pytest.raises(StepFailure, match="dependent rows"):
        constrained_step(Hb, np.ones(N), support, Js, np.zeros(4))


def test_singular_hessian_is_refused():
    Hb, _ = banded_hessian(17)  # linear motions cost nothing and no constraint pins them
    support = np.array([20])
    with pytest.raises(IndefiniteHessian):
        KKTSystem(Hb, 0.0, support, np.ones((1, 1)))


def _unit_rows_case(seed: int):
    """Start and goal rows fixing one parameter each, a contact row on the interior that also touches a
    fixed column: (support, Js, dense Jh (5, N))."""
    rng = np.random.default_rng(seed)
    support = np.array([0, 1, 17, 18, 19, 38, 39])
    Js = np.zeros((5, 7))
    Js[0, 0], Js[1, 1], Js[2, 6] = 2.0, 0.7, -1.5  # unit rows: w_0, w_1, w_39 fixed
    Js[3, 2:5] = rng.normal(size=3)
    Js[4, [0, 3, 4]] = rng.normal(size=3)  # touches the fixed column 0
    Jh = np.zeros((5, N))
    Jh[:, support] = Js
    return support, Js, Jh


def test_rows_that_fix_a_parameter_are_eliminated_exactly():
    from corl.trajectory.solver.factor import KKTStructure

    _, H = banded_hessian(18)
    support, Js, Jh = _unit_rows_case(19)
    structure = KKTStructure(support, Js != 0.0)
    np.testing.assert_array_equal(structure.fixed_cols, [0, 1, 39])
    H = H + Jh.T @ Jh  # the SQP adds 2 mu Jh^T Jh: definite
    Hb = BandedSPD.from_sparse(sp.csr_matrix(H))
    rng = np.random.default_rng(20)
    for shift in (0.0, 0.3):
        b, c = rng.normal(size=N), rng.normal(size=5)
        a, lam = KKTSystem(Hb, shift, support, Js, structure).solve(b, c)
        d_ref, lam_ref = dense_kkt(H, Jh, b, c, nu=shift, u=np.zeros(N))
        np.testing.assert_allclose(a, d_ref, rtol=1e-9, atol=1e-10 * np.abs(d_ref).max())
        np.testing.assert_allclose(lam, lam_ref, rtol=1e-9, atol=1e-10 * np.abs(lam_ref).max())
    g, h = 10.0 * rng.normal(size=N), 0.01 * rng.normal(size=5)
    u = rng.normal(size=N)
    d, lam, z, nu = constrained_step(Hb, g, support, Js, h, u, 1.2 * np.linalg.norm(u), structure=structure)
    _assert_ball_step_is_optimal(H, Jh, g, h, u, 1.2 * np.linalg.norm(u), d, lam, z, nu)


def _condensable_case(seed: int, N2: int = 60, mu: float = 1.0, curvature_scale: float = 0.3):
    """H = H_J + mu 2 Jh^T Jh + curvature, with start and goal fixed and a contact on columns 25..29:
    (BandedSum, dense H, support, Js, Jh, pattern)."""
    from corl.trajectory.solver.banded import BandedSum, SupportGram, SupportPattern

    rng = np.random.default_rng(seed)
    D = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(N2 - 2, N2)).toarray()
    H_J = 2.0 * D.T @ np.diag(rng.uniform(0.5, 2.0, N2 - 2)) @ D
    base = BandedSPD.from_sparse(sp.csr_matrix(H_J), 4)
    support = np.array([0, 1, 25, 26, 27, 28, 29, N2 - 2, N2 - 1])
    touched = np.zeros((6, 9), dtype=bool)
    touched[[0, 1, 2, 3], [0, 1, 7, 8]] = True
    touched[4:, 2:7] = True
    pattern = SupportPattern(support, touched)
    Js = np.where(touched, rng.normal(size=touched.shape), 0.0)
    Jh = np.zeros((6, N2))
    Jh[:, support] = Js
    R = rng.normal(size=(5, 5))
    C = curvature_scale * (R @ R.T)  # semi-definite for a positive scale
    gram = SupportGram(support, 2.0 * mu * Js.T @ Js, N2, pattern.pairs, Js, pattern)
    H = BandedSum(base, (gram, SupportGram.dense_block(np.arange(25, 30), C, N2)))
    dense = H_J + 2.0 * mu * Jh.T @ Jh
    dense[25:30, 25:30] += C
    return H, dense, support, Js, Jh, pattern


def test_condensation_on_the_constraint_window_matches_the_dense_kkt():
    from corl.trajectory.solver.factor import structure_of

    rng = np.random.default_rng(21)
    for mu in (1.0, 0.2):  # a new mu reuses the factors of the two sides (same H_J and shift)
        H, dense, support, Js, Jh, _ = _condensable_case(22, mu=mu)
        structure = structure_of(H.blocks[0])
        for shift in (0.0, 0.7, 0.0):
            kkt = KKTSystem(H, shift, support, Js, structure)
            assert kkt.cond is not None and structure.window == (25, 5)
            b, c = rng.normal(size=60), rng.normal(size=6)
            a, lam = kkt.solve(b, c)
            q = Jh.shape[0]
            K = np.block([[dense + shift * np.eye(60), Jh.T], [Jh, np.zeros((q, q))]])
            ref = np.linalg.solve(K, -np.concatenate([b, c]))
            np.testing.assert_allclose(a, ref[:60], rtol=1e-9, atol=1e-10 * np.abs(ref[:60]).max())
            np.testing.assert_allclose(lam, ref[60:], rtol=1e-9, atol=1e-10 * np.abs(ref[60:]).max())
        assert len(structure.sides) == 2  # shift 0 and 0.7 kept


def test_condensation_refuses_an_indefinite_window_and_steps_aside_near_the_ends():
    from corl.trajectory.solver.banded import BandedSum, SupportGram
    from corl.trajectory.solver.factor import structure_of

    H, dense, support, Js, Jh, _ = _condensable_case(23, curvature_scale=-50.0)
    assert np.linalg.eigvalsh(dense)[0] < 0
    with pytest.raises(IndefiniteHessian):
        KKTSystem(H, 0.0, support, Js, structure_of(H.blocks[0]))
    # a curvature block outside the window: the direct band factorization, same answer
    H, dense, support, Js, Jh, _ = _condensable_case(24)
    outside = SupportGram.dense_block(np.arange(40, 43), 0.1 * np.eye(3), 60)
    H2 = BandedSum(H.base, H.blocks + (outside,))
    dense2 = dense.copy()
    dense2[40:43, 40:43] += 0.1 * np.eye(3)
    kkt = KKTSystem(H2, 0.0, support, Js, structure_of(H.blocks[0]))
    assert kkt.cond is None
    rng = np.random.default_rng(25)
    b, c = rng.normal(size=60), rng.normal(size=6)
    a, _ = kkt.solve(b, c)
    K = np.block([[dense2, Jh.T], [Jh, np.zeros((6, 6))]])
    ref = np.linalg.solve(K, -np.concatenate([b, c]))[:60]
    np.testing.assert_allclose(a, ref, rtol=1e-9, atol=1e-10 * np.abs(ref).max())


@pytest.mark.parametrize("order", [[0, 1, 2, 3, 4, 5], [4, 0, 5, 2, 1, 3]])
def test_schur_complement_with_interleaved_row_groups_matches_the_dense_kkt(order):
    """Contact rows in groups by where they start (one forward substitution each), listed in an order
    that makes a group's rows non-consecutive: W is filled per group all the same."""
    Hb, H = banded_hessian(3)
    rng = np.random.default_rng(4)
    spans = [(0, 2), (5, 7), (6, 8), (25, 27), (26, 28), (38, 40)]
    Jh = np.zeros((len(spans), N))
    for i, (a, b) in enumerate(spans[j] for j in order):
        Jh[i, a:b] = rng.normal(size=b - a)
    support = np.flatnonzero(Jh.any(axis=0))
    Js = Jh[:, support]
    Hb_aug = (1.0 * BandedSPD.from_sparse(sp.csr_matrix(Jh.T @ Jh))) + Hb
    b, c = rng.normal(size=N), rng.normal(size=Jh.shape[0])
    a, lam = KKTSystem(Hb_aug, 0.2, support, Js).solve(b, c)
    d_ref, lam_ref = dense_kkt(H + Jh.T @ Jh, Jh, b, c, nu=0.2, u=np.zeros(N))
    np.testing.assert_allclose(a, d_ref, rtol=1e-9, atol=1e-10 * np.abs(d_ref).max())
    np.testing.assert_allclose(lam, lam_ref, rtol=1e-9, atol=1e-10 * np.abs(lam_ref).max())
