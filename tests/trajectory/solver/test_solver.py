"""Tests of the constrained Gauss-Newton solver (Eq. 8) and the projection (Eq. 18)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import minimize

from corl.errors import InputError, NumericalError
from corl.trajectory.solver.linalg import factorize_spd, solve_spd, trust_region_step
from corl.trajectory.solver import FunctionProblem, SolverConfig, project, solve

THETA0 = math.atan2(0.4, 0.3)


# -- problems ------------------------------------------------------------------------------------
def circle_residuals(w):
    """Synthetic benchmark (Sec. VIII-A): J(w) = (w1^2 + w2^2 - 1)^2."""
    return np.array([w[0] ** 2 + w[1] ** 2 - 1.0]), np.array([[2.0 * w[0], 2.0 * w[1]]])


def angle_constraint(theta):
    """h(w) = atan2(w2, w1) - theta with dh/dw = (-w2, w1) / (w1^2 + w2^2)."""

    def equalities(w):
        s = w[0] ** 2 + w[1] ** 2
        return np.array([math.atan2(w[1], w[0]) - theta]), np.array([[-w[1] / s, w[0] / s]])

    return equalities


def paper_problem(theta=THETA0):
    return FunctionProblem(circle_residuals, angle_constraint(theta))


class RandomProblem:
    """n=6 parameters, p=8 mildly nonlinear residuals, q=2 nonlinear equalities."""

    def __init__(self, seed=0, sparse=False):
        rng = np.random.default_rng(seed)
        self.A = rng.normal(size=(8, 6))
        self.B = 0.3 * rng.normal(size=(8, 6))
        self.c = rng.normal(size=8)
        self.d = rng.normal(size=6)
        self.sparse = sparse

    def _jac(self, J):
        return sp.csr_matrix(J) if self.sparse else J

    def residuals(self, w):
        s = self.B @ w
        return self.A @ w + 0.5 * np.sin(s) - self.c, self._jac(self.A + 0.5 * np.cos(s)[:, None] * self.B)

    def equalities(self, w):
        h = np.array([w @ w - 2.0, self.d @ w + 0.2 * w[0] * w[1] - 0.3])
        J = np.vstack([2.0 * w, self.d + 0.2 * np.array([w[1], w[0], 0, 0, 0, 0])])
        return h, self._jac(J)

    def cost(self, w):
        r, _ = self.residuals(w)
        return float(r @ r)


def slsqp(problem, w0, *, center=None, radius=None):
    cons = [{"type": "eq", "fun": lambda w: problem.equalities(w)[0], "jac": lambda w: problem.equalities(w)[1]}]
    if radius is not None:
        ball = {"type": "ineq", "fun": lambda w: radius**2 - (w - center) @ (w - center)}
        cons.append({**ball, "jac": lambda w: -2 * (w - center)})
    res = minimize(
        lambda w: problem.cost(w),
        w0,
        jac=lambda w: 2 * problem.residuals(w)[1].T @ problem.residuals(w)[0],
        constraints=cons,
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert res.success, res.message
    return res.x


# -- linear algebra seam ---------------------------------------------------------------------------
def test_solve_spd_dense_and_sparse_agree_with_numpy():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(9, 5))
    H, b = J.T @ J, rng.normal(size=5)
    expected = np.linalg.solve(H + 0.3 * np.eye(5), b)
    np.testing.assert_allclose(solve_spd(H, b, 0.3), expected, rtol=1e-12)
    np.testing.assert_allclose(solve_spd(sp.csr_matrix(H), b, 0.3), expected, rtol=1e-10)
    np.testing.assert_allclose(factorize_spd(H).solve(b), np.linalg.solve(H, b), rtol=1e-10)


def test_solve_spd_singular_dense_uses_jitter_and_stays_finite():
    H = np.array([[1.0, 1.0], [1.0, 1.0]])  # rank 1: Cholesky fails without jitter
    x = solve_spd(H, np.array([1.0, 1.0]))
    assert np.all(np.isfinite(x))
    np.testing.assert_allclose(H @ x, [1.0, 1.0], rtol=1e-4)


@pytest.mark.parametrize("sparse", [False, True])
def test_trust_region_step_solves_the_ball_subproblem(sparse):
    rng = np.random.default_rng(6)
    J = rng.normal(size=(3, 5))  # rank 3: H is singular, the damping makes it definite
    H, g, damping, radius = J.T @ J, rng.normal(size=5), 1e-3, 0.1
    u = rng.normal(size=5)
    u *= 0.5 * radius / np.linalg.norm(u)
    d, z = trust_region_step(sp.csr_matrix(H) if sparse else H, g, damping, u, radius)
    assert z is not None
    np.testing.assert_allclose(z, u + d, atol=1e-15)
    assert np.linalg.norm(z) == pytest.approx(radius, rel=1e-12)
    # KKT of the subproblem: (H + damping I) d + g + nu z = 0 with nu >= 0.
    grad = (H + damping * np.eye(5)) @ d + g
    nu = -(grad @ z) / (z @ z)
    assert nu > 0
    np.testing.assert_allclose(grad + nu * z, 0.0, atol=1e-9 * np.linalg.norm(g))


def test_trust_region_step_inside_the_ball_is_the_damped_newton_step():
    H, g = np.array([[2.0, 0.5], [0.5, 1.0]]), np.array([0.01, -0.02])
    d, z = trust_region_step(H, g, 1e-6, np.zeros(2), 1.0)
    assert z is None
    np.testing.assert_allclose(d, -np.linalg.solve(H + 1e-6 * np.eye(2), g), rtol=1e-12)


# -- unconstrained and paper problem ---------------------------------------------------------------
def test_unconstrained_linear_least_squares_matches_lstsq():
    rng = np.random.default_rng(2)
    A, b = rng.normal(size=(10, 4)), rng.normal(size=10)
    result = solve(FunctionProblem(lambda w: (A @ w - b, A)), np.zeros(4))
    expected = np.linalg.lstsq(A, b, rcond=None)[0]
    assert result.converged, result.status
    np.testing.assert_allclose(result.w, expected, atol=1e-10 * np.abs(expected).max())
    assert result.cost == pytest.approx(float(np.sum((A @ expected - b) ** 2)), rel=1e-12)
    assert result.multipliers.shape == (0,)


def test_paper_problem_without_trust_region_reaches_circle_at_angle():
    result = solve(paper_problem(), [0.3, 0.4])
    assert result.converged, result.status
    np.testing.assert_allclose(result.w, [math.cos(THETA0), math.sin(THETA0)], atol=1e-8)
    assert result.constraint_error <= 1e-6


def test_paper_problem_trust_region_step_is_exact_and_improves():
    w0 = np.array([0.3, 0.4])
    result = solve(paper_problem(), w0, radius=1e-3)
    assert result.converged, result.status
    assert np.linalg.norm(result.w - w0) <= 1e-3 * (1 + 1e-12)
    assert result.constraint_error <= 1e-6
    assert result.cost < circle_residuals(w0)[0][0] ** 2
    assert result.trust_region_active
    # Exact solution of Eq. 8 here: move eps_max along the ray towards the circle.
    np.testing.assert_allclose(result.w, w0 * (1 + 1e-3 / 0.5), atol=1e-12)


def test_repeated_trust_region_calls_reach_the_circle():
    problem, w = paper_problem(), np.array([0.3, 0.4])
    for _ in range(600):
        result = solve(problem, w, radius=1e-3)  # center defaults to the last result (Alg. 1, step 1)
        assert result.converged, result.status
        assert np.linalg.norm(result.w - w) <= 1e-3 * (1 + 1e-12)
        w = result.w
    np.testing.assert_allclose(w, [math.cos(THETA0), math.sin(THETA0)], atol=1e-8)


def test_trust_region_call_is_fast_on_the_paper_problem():
    problem, w = paper_problem(), np.array([0.3, 0.4])
    start = time.perf_counter()
    for _ in range(200):
        w = solve(problem, w, radius=1e-3).w
    per_call = (time.perf_counter() - start) / 200
    assert per_call < 2e-3  # target 0.3 ms; loose bound so a busy machine does not fail the test


# -- KKT and trust region on a random problem -------------------------------------------------------
def test_random_problem_matches_slsqp_and_satisfies_kkt():
    problem = RandomProblem()
    w0 = np.full(6, 0.5)
    result = solve(problem, w0, config=SolverConfig.precise())
    assert result.converged, result.status
    reference = slsqp(problem, w0)
    np.testing.assert_allclose(result.w, reference, atol=1e-6)
    r, Jr = problem.residuals(result.w)
    h, Jh = problem.equalities(result.w)
    grad = 2 * Jr.T @ r
    nu = np.linalg.lstsq(Jh.T, -grad, rcond=None)[0]
    assert np.linalg.norm(grad + Jh.T @ nu) <= 1e-7 * (1 + np.linalg.norm(grad))
    assert np.max(np.abs(h)) <= 1e-10
    np.testing.assert_allclose(result.multipliers, nu, rtol=1e-5, atol=1e-7)


def test_trust_region_holds_at_every_iterate_and_matches_slsqp():
    problem = RandomProblem(seed=3)
    center = np.full(6, 0.5)
    feasible = project(problem, center, config=SolverConfig.precise()).w
    radius = 0.05
    result = solve(problem, feasible, center=feasible, radius=radius, config=SolverConfig.precise())
    assert result.converged, result.status
    assert len(result.history) >= 2
    for record in result.history:
        assert np.linalg.norm(record.w - feasible) <= radius * (1 + 1e-12)
    assert np.linalg.norm(result.w - feasible) <= radius * (1 + 1e-12)
    assert result.cost < problem.cost(feasible)
    reference = slsqp(problem, feasible, center=feasible, radius=radius)
    np.testing.assert_allclose(result.w, reference, atol=1e-6)


def test_restoration_reaches_the_tolerance_on_the_ball_from_a_stalled_point():
    """What the solver does when L_A stalls at a violation set by the BLAS kernel's rounding
    (3.4e-10 with OpenBLAS's Haswell kernel on the test above, 4e-11 with SkylakeX): minimum-norm
    Newton steps on h, tangent to the ball, finish the job. Forced here on any machine by starting
    from a point on the ball that misses h = 0 by a few times the tolerance."""
    from corl.trajectory.solver.al import restore
    from corl.trajectory.solver.state import SolveState

    problem = RandomProblem(seed=3)
    center = project(problem, np.full(6, 0.5), config=SolverConfig.precise()).w
    radius = 0.05
    reference = slsqp(problem, center, center=center, radius=radius)
    tangent = np.random.default_rng(0).normal(size=6)
    tangent -= (tangent @ (reference - center)) / np.linalg.norm(reference - center) ** 2 * (reference - center)
    w = reference + 2e-10 * tangent / np.linalg.norm(tangent)  # off h = 0 by a few 1e-10, along the ball
    w = center + (w - center) * (radius / np.linalg.norm(w - center))  # exactly on the ball
    config = SolverConfig.precise()
    state = SolveState(problem, config, center, radius)
    start = state.evaluate(w)
    scale = 1.0 + float(np.max(np.abs(problem.equalities(w)[1]))) * np.linalg.norm(w)  # size of h's terms
    assert config.tol_constraint < start.err <= 10 * config.tol_constraint  # a stall, not a far miss
    restored = restore(state, start)
    assert restored is not None
    assert restored.err <= config.tol_constraint
    assert restored.err <= 1e3 * np.finfo(float).eps * scale  # Newton on h converges to rounding level
    assert np.linalg.norm(restored.w - center) <= radius * (1 + 4 * np.finfo(float).eps)
    assert np.linalg.norm(restored.w - w) <= 10 * start.err  # a step the size of the violation, no more


def test_restoration_declines_a_violation_far_above_the_tolerance():
    from corl.trajectory.solver.al import restore
    from corl.trajectory.solver.state import SolveState

    problem = RandomProblem(seed=3)
    w = np.full(6, 0.5)  # max|h| of order 1: genuinely infeasible at tol 1e-10, not a stall
    state = SolveState(problem, SolverConfig.precise(), None, np.inf)
    assert restore(state, state.evaluate(w)) is None


def test_start_outside_the_ball_is_moved_inside():
    center = np.array([0.3, 0.4])
    result = solve(paper_problem(), [0.9, 1.2], center=center, radius=1e-2)
    for record in result.history:
        assert np.linalg.norm(record.w - center) <= 1e-2 * (1 + 1e-12)


# -- projection (Eq. 18) -----------------------------------------------------------------------------
def test_projection_onto_linear_constraints_matches_closed_form():
    rng = np.random.default_rng(4)
    A, b, w_star = rng.normal(size=(2, 5)), rng.normal(size=2), rng.normal(size=5)
    result = project(lambda w: (A @ w - b, A), w_star, config=SolverConfig.precise())
    expected = w_star - A.T @ np.linalg.solve(A @ A.T, A @ w_star - b)
    assert result.converged, result.status
    np.testing.assert_allclose(result.w, expected, atol=1e-9)
    assert result.cost == pytest.approx(float(np.sum((expected - w_star) ** 2)), rel=1e-7)


def test_projection_onto_angle_on_the_circle_problem():
    result = project(angle_constraint(0.5), [1.0, 0.0])
    assert result.converged, result.status
    np.testing.assert_allclose(result.w, math.cos(0.5) * np.array([math.cos(0.5), math.sin(0.5)]), atol=1e-7)


def test_projection_with_sparse_jacobian_matches_dense():
    rng = np.random.default_rng(5)
    A, b, w_star = rng.normal(size=(2, 5)), rng.normal(size=2), rng.normal(size=5)
    dense = project(lambda w: (A @ w - b, A), w_star)
    sparse = project(lambda w: (A @ w - b, sp.csr_matrix(A)), w_star)
    np.testing.assert_allclose(sparse.w, dense.w, atol=1e-10 * np.abs(dense.w).max())


# -- sparse Jacobians ----------------------------------------------------------------------------------
@pytest.mark.parametrize("radius", [math.inf, 0.05])
def test_sparse_jacobians_give_the_dense_result(radius):
    w0 = np.full(6, 0.5)
    w0 = project(RandomProblem(), w0).w
    dense = solve(RandomProblem(), w0, radius=radius)
    sparse = solve(RandomProblem(sparse=True), w0, radius=radius)
    assert dense.converged and sparse.converged, (dense.status, sparse.status)
    np.testing.assert_allclose(sparse.w, dense.w, atol=1e-9)


def test_mixed_sparse_and_dense_jacobians_are_accepted():
    problem = RandomProblem()
    def sparse_residuals(w):
        r, Jr = problem.residuals(w)
        return r, sp.csr_matrix(Jr)

    mixed = FunctionProblem(sparse_residuals, problem.equalities)
    w0 = np.full(6, 0.5)
    np.testing.assert_allclose(solve(mixed, w0).w, solve(problem, w0).w, atol=1e-9)


# -- failures ---------------------------------------------------------------------------------------------
def test_inconsistent_constraints_return_not_converged_quickly():
    def equalities(w):
        return np.array([w[0] - 1.0, w[0] - 2.0]), np.array([[1.0, 0.0], [1.0, 0.0]])

    start = time.perf_counter()
    result = solve(FunctionProblem(lambda w: (w.copy(), np.eye(2)), equalities), [0.0, 0.0])
    assert time.perf_counter() - start < 1.0
    assert not result.converged
    assert "cannot be satisfied" in result.status
    assert np.all(np.isfinite(result.w))
    assert result.w[0] == pytest.approx(1.5, abs=1e-6)


def test_penalty_limit_stops_inconsistent_constraints():
    def equalities(w):
        return np.array([w[0] - 1.0, w[0] - 2.0]), np.array([[1.0, 0.0], [1.0, 0.0]])

    problem = FunctionProblem(lambda w: (w.copy(), np.eye(2)), equalities)
    result = solve(problem, [0.0, 0.0], config=SolverConfig(mu_max=5.0))
    assert not result.converged
    assert "penalty reached" in result.status
    assert result.outer_iterations == 1


def test_trust_region_too_small_to_reach_constraints_returns_not_converged():
    # Start at angle 0.9, ask for angle 0.93: out of reach within radius 1e-3 at |w| = 0.5.
    w0 = 0.5 * np.array([math.cos(0.9), math.sin(0.9)])
    result = solve(paper_problem(0.93), w0, radius=1e-3)
    assert not result.converged
    assert "trust region" in result.status
    assert np.linalg.norm(result.w - w0) <= 1e-3 * (1 + 1e-12)
    assert result.constraint_error < abs(0.93 - 0.9)  # it still moved towards h = 0


def test_nan_residuals_raise_numerical_error():
    problem = FunctionProblem(lambda w: (np.array([np.nan]), np.ones((1, 2))))
    with pytest.raises(NumericalError, match="NaN"):
        solve(problem, [0.0, 0.0])


def test_nan_at_a_trial_point_raises_numerical_error():
    def residuals(w):
        with np.errstate(invalid="ignore"):
            value = np.sqrt(w[0])  # NaN once the step crosses w1 < 0
        return np.array([value + 1.0]), np.array([[0.5 / max(value, 1e-3)]])

    with pytest.raises(NumericalError):
        solve(FunctionProblem(residuals), [1.0])


def test_bad_shapes_and_settings_raise_input_error():
    with pytest.raises(InputError, match=r"expected \(1, 2\)"):
        solve(FunctionProblem(lambda w: (np.array([1.0]), np.ones((1, 3)))), [0.0, 0.0])
    with pytest.raises(InputError, match="radius"):
        solve(paper_problem(), [0.3, 0.4], radius=0.0)
    with pytest.raises(InputError, match="center"):
        solve(paper_problem(), [0.3, 0.4], center=[0.0], radius=1.0)
    with pytest.raises(InputError, match="mu_growth"):
        SolverConfig(mu_growth=1.0)
    with pytest.raises(InputError, match="max_iterations"):
        SolverConfig(max_iterations=0)


def test_iteration_budget_stops_with_a_message():
    result = solve(paper_problem(), [0.3, 0.4], config=SolverConfig(max_iterations=1))
    assert not result.converged
    assert "max_iterations" in result.status
    assert result.iterations == 1


# -- small dense trust-region path and the manifold projection -----------------------------------------
@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_small_dense_trust_region_step_matches_the_factorized_one(n):
    rng = np.random.default_rng(10 + n)
    for _ in range(50):
        J = rng.normal(size=(rng.integers(1, n + 2), n)) * 10 ** rng.uniform(-2, 2)
        H, g = J.T @ J, rng.normal(size=n)
        damping, radius = 10 ** rng.uniform(-8, 0) * np.abs(H).max(), 10 ** rng.uniform(-3, 1)
        u = rng.normal(size=n)
        u *= rng.uniform(0, 1) * radius / np.linalg.norm(u)
        d, z = trust_region_step(H, g, damping, u, radius)  # eigenbasis path (n <= 16)
        d_ref, z_ref = trust_region_step(sp.csc_matrix(H), g, damping, u, radius)  # factorizations
        assert (z is None) == (z_ref is None)
        np.testing.assert_allclose(d, d_ref, rtol=1e-7, atol=1e-9 * (np.linalg.norm(d_ref) + radius))


def test_model_step_reports_the_step_norm_and_model_decrease():
    from corl.trajectory.solver.linalg import model_step

    rng = np.random.default_rng(11)
    for n in (2, 4, 20):
        J = rng.normal(size=(n + 1, n))
        H, g, u = J.T @ J, rng.normal(size=n), np.zeros(n)
        d, z, dn, predicted = model_step(H, g, 1e-6, u, 0.05)
        assert z is not None
        assert dn == pytest.approx(np.linalg.norm(d), rel=1e-12)
        assert predicted == pytest.approx(-(g @ d + 0.5 * d @ H @ d), rel=1e-9)


@pytest.mark.parametrize("offset", [0.5, 1.0, 1.5, -1.5])
def test_projection_far_along_the_angle_is_exact_and_cheap(offset):
    # Closest point to w* on the ray at angle a + offset: cos(offset) along that ray. The multiplier
    # grows like tan(offset), where the augmented Lagrangian alone needs dozens of evaluations.
    a = 0.3
    w_star = np.array([math.cos(a), math.sin(a)])
    theta = a + offset
    result = project(angle_constraint(theta), w_star)
    assert result.converged, result.status
    assert result.constraint_error <= 1e-6
    expected = math.cos(offset) * np.array([math.cos(theta), math.sin(theta)])
    np.testing.assert_allclose(result.w, expected, atol=1e-9)
    assert result.evaluations <= 12
    assert result.cost == pytest.approx(float(np.sum((expected - w_star) ** 2)), rel=1e-9)


def test_projection_without_closest_point_still_reports_failure():
    # Beyond pi/2 the infimum sits at the origin, where h is singular: not attained, not converged
    # (the learner then reaches theta by continuation).
    w_star = np.array([1.0, 0.0])
    result = project(angle_constraint(2.0), w_star)
    assert not result.converged
    assert np.all(np.isfinite(result.w))


def test_projection_on_a_curved_manifold_satisfies_kkt():
    # Ellipse h = w1^2 / 4 + w2^2 - 1: the tangent steps must follow the curvature.
    def ellipse(w):
        return np.array([w[0] ** 2 / 4 + w[1] ** 2 - 1.0]), np.array([[w[0] / 2, 2 * w[1]]])

    for w_star in ([0.3, 0.1], [3.0, 2.0], [-0.5, 1.7]):
        w_star = np.asarray(w_star)
        result = project(ellipse, w_star, config=SolverConfig.precise())
        assert result.converged, result.status
        h, Jh = ellipse(result.w)
        assert abs(h[0]) <= 1e-10
        normal = Jh[0] / np.linalg.norm(Jh[0])
        offset = result.w - w_star
        np.testing.assert_allclose(offset - (offset @ normal) * normal, 0.0, atol=1e-9)
        # The multiplier nu solves 2 (w - w*) + Jh^T nu = 0.
        np.testing.assert_allclose(2 * offset + Jh[0] * result.multipliers[0], 0.0, atol=1e-8)


def test_projection_with_large_sparse_jacobian_matches_dense():
    rng = np.random.default_rng(12)
    n, q = 400, 5
    A = sp.random(q, n, density=0.05, random_state=3, format="csr") + sp.eye(q, n, k=n - q, format="csr")
    b, w_star = rng.normal(size=q), 0.1 * rng.normal(size=n)

    def equalities(w, sparse):
        Aw = A @ w
        J = sp.diags(1 + 0.3 * np.cos(Aw)) @ A
        return Aw + 0.3 * np.sin(Aw) - b, (J.tocsr() if sparse else J.toarray())

    sparse = project(lambda w: equalities(w, True), w_star)
    dense = project(lambda w: equalities(w, False), w_star)
    assert sparse.converged and dense.converged, (sparse.status, dense.status)
    assert sparse.constraint_error <= 1e-6
    np.testing.assert_allclose(sparse.w, dense.w, atol=1e-9)


def test_projection_call_is_fast_on_the_paper_problem():
    w_star = np.array([math.cos(0.3), math.sin(0.3)])
    start = time.perf_counter()
    for k in range(50):
        project(angle_constraint(0.3 + 1.5 * math.sin(k)), w_star)
    per_call = (time.perf_counter() - start) / 50
    assert per_call < 5e-3  # target 1 ms; loose bound so a busy machine does not fail the test
