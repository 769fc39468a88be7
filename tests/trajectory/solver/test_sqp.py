"""SQP on banded trajectory problems (corl.trajectory.solver.sqp): KKT of Eq. 8, the trust region, the
hand-over to the augmented Lagrangian, and iteration counts independent of the number of knots."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from corl.errors import InputError
from corl.trajectory.bspline import BSpline
from corl.trajectory.features import (
    TaskSpaceFeature,
    TrajectoryProblem,
    acceleration_feature,
    configuration_feature,
)
from corl.trajectory.solver import FunctionProblem, SolverConfig, SolverMethod, project, solve

SQP = SolverConfig.trajectory()
AL = replace(SQP, method="al")


def circle_problem():
    """The 2-D synthetic task (Sec. VIII-A): J = (|w|^2 - 1)^2 on the ray at angle 0.9 (dense, tiny)."""

    def residuals(w):
        return np.array([w @ w - 1.0]), 2.0 * w[None, :]

    def angle(w):
        return np.array([np.arctan2(w[1], w[0]) - 0.9]), np.array([[-w[1], w[0]]]) / (w @ w)

    return FunctionProblem(residuals, angle)


def _grad(problem, w):
    r, Jr = problem.residuals(w)
    return 2 * Jr.T @ r


def test_method_setting_is_validated_and_the_presets_choose():
    assert SolverConfig().method is SolverMethod.SQP  # SQP where the problem is banded, AL elsewhere
    assert SolverConfig.trajectory().method is SolverMethod.SQP
    assert SolverConfig(method="sqp").method is SolverMethod.SQP
    with pytest.raises(InputError, match="method must be"):
        SolverConfig(method="newton")


def test_dense_problems_keep_the_augmented_lagrangian():
    with_sqp = solve(circle_problem(), [0.3, 0.4], radius=1e-2, config=SolverConfig(method="sqp"))
    without = solve(circle_problem(), [0.3, 0.4], radius=1e-2)
    assert with_sqp.iterations == without.iterations and "SQP" not in with_sqp.status
    np.testing.assert_array_equal(with_sqp.w, without.w)


def test_sqp_with_active_trust_region_satisfies_kkt_and_matches_slsqp(reaching):
    _, problem, w0 = reaching()
    center = project(problem, w0, config=SolverConfig.precise()).w  # Alg. 1, step 1 starts feasible
    radius = 0.2
    result = solve(problem, center, radius=radius, config=SQP)
    assert result.converged and "SQP" in result.status, result.status
    assert result.outer_iterations == 1 and result.trust_region_active
    for record in result.history:
        assert np.linalg.norm(record.w - center) <= radius * (1 + 1e-12)
    # KKT of Eq. 8 with the ball active: grad J + Jh^T nu + 2 kappa (w - center) = 0, kappa >= 0.
    h, Jh = problem.equalities(result.w)
    grad, offset = _grad(problem, result.w), result.w - center
    A = np.column_stack([Jh.toarray().T, 2 * offset])
    coef = np.linalg.lstsq(A, -grad, rcond=None)[0]
    assert np.linalg.norm(grad + A @ coef) <= 1e-7 * np.linalg.norm(grad)
    assert coef[-1] > 0 and np.abs(h).max() <= 1e-8
    np.testing.assert_allclose(result.multipliers, coef[:-1], rtol=1e-5, atol=1e-7 * np.abs(coef).max())
    equality = {"type": "eq", "fun": lambda w: problem.equalities(w)[0]}
    equality["jac"] = lambda w: problem.equalities(w)[1].toarray()
    ball = {"type": "ineq", "fun": lambda w: radius**2 - (w - center) @ (w - center), "jac": lambda w: 2 * (center - w)}
    reference = minimize(
        problem.cost,
        center,
        jac=lambda w: _grad(problem, w),
        constraints=[equality, ball],
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 500},
    )
    if not reference.success and _scipy_before("1.16"):  # SLSQP was rewritten in 1.16; the KKT check above holds
        pytest.skip(f"scipy's SLSQP before 1.16 stops early here ({reference.message}): no reference to compare")
    # SLSQP's line search may stop with "positive directional derivative" once its ftol = 1e-14 is
    # below what the machine's rounding allows (it does with OpenBLAS's Sandybridge kernel); the
    # point it reached is then still the reference, provided it is feasible to the same tolerance.
    assert reference.success or reference.status == 8, reference.message
    assert np.abs(problem.equalities(reference.x)[0]).max() <= 1e-8
    assert result.cost == pytest.approx(reference.fun, rel=1e-7)
    np.testing.assert_allclose(result.w, reference.x, atol=1e-5)


def test_sqp_hands_over_to_the_augmented_lagrangian_when_the_ball_is_out_of_reach(reaching):
    _, problem, w0 = reaching()  # w0 misses the contact: its linearization needs > 0.2
    result = solve(problem, w0, radius=0.2, config=SQP)
    assert "SQP iterations" in result.status and "trust region" in result.status
    for record in result.history:
        assert np.linalg.norm(record.w - w0) <= 0.2 * (1 + 1e-9)
    alone = solve(problem, w0, radius=0.2, config=AL)
    np.testing.assert_allclose(result.w, alone.w, atol=1e-12)
    assert result.converged == alone.converged


def test_dependent_constraints_fall_back_and_still_converge(reaching):
    spline, problem, w0 = reaching()
    start, goal = spline.positions(w0, [0.0, 2.0])
    cost = [acceleration_feature(spline, 2 * spline.num_control_points)]
    ends = [configuration_feature(spline, 0.0, start), configuration_feature(spline, 2.0, goal)]
    single = TrajectoryProblem(spline.n, cost, [*ends, *problem._eq_other])
    doubled = TrajectoryProblem(spline.n, cost, [ends[0], *ends, *problem._eq_other])  # dependent rows of dh/dw
    result = solve(doubled, w0, config=SQP)
    assert result.converged, result.status
    assert "dependent rows" in result.status
    reference = solve(single, w0, config=SQP)
    assert "SQP" in reference.status and reference.outer_iterations == 1
    assert result.cost == pytest.approx(reference.cost, rel=1e-6)


def test_iteration_budget_stops_sqp_with_a_message(reaching):
    _, problem, w0 = reaching()
    result = solve(problem, w0, config=SolverConfig(method="sqp", max_iterations=2, tol_constraint=1e-8))
    assert not result.converged
    assert "max_iterations" in result.status and "SQP" in result.status
    assert result.iterations == 2 and result.outer_iterations == 1


def test_sqp_without_trust_region_matches_the_augmented_lagrangian(reaching):
    _, problem, w0 = reaching()
    sqp, al = solve(problem, w0, config=SQP), solve(problem, w0, config=AL)
    assert sqp.converged and al.converged
    assert sqp.iterations < al.iterations
    assert sqp.cost == pytest.approx(al.cost, rel=1e-7)
    np.testing.assert_allclose(sqp.multipliers, al.multipliers, rtol=1e-4, atol=1e-6 * np.abs(al.multipliers).max())


# -- iterations independent of the number of knots (issue #3) -------------------------------------
def benchmark_problem(fk, fk_hessian, P: int):
    """benchmarks/motion_opt.py at P control points: squared accelerations, start and goal fixed, the
    hand 8 cm off a non-smooth demonstration at t_c = 0.45 T."""
    T = 5.0
    spline = BSpline(P, 7, T)
    waypoints = np.array(
        [
            [0.0, 0.3, 0.0, -1.2, 0.0, 0.8, 0.0],
            [0.3, 0.6, 0.2, -1.0, 0.3, 0.9, 0.2],
            [0.6, 0.8, 0.1, -0.7, 0.2, 1.1, 0.5],
            [0.7, 0.9, -0.2, -0.5, -0.1, 1.0, 0.6],
            [0.5, 0.6, -0.3, -0.8, -0.3, 0.7, 0.3],
            [0.2, 0.4, 0.0, -1.1, 0.0, 0.8, 0.1],
        ]
    )
    dense = np.linspace(0.0, T, 4 * P)
    s = np.linspace(0.0, T, len(waypoints))
    demo = np.stack([np.interp(dense, s, waypoints[:, j]) for j in range(7)], axis=1)
    w0 = spline.fit(dense, demo)
    first, last = spline.positions(w0, [0.0, T])
    target = fk(spline.positions(w0, [0.45 * T])[0])[0] + np.array([0.05, -0.04, 0.06])
    problem = TrajectoryProblem(
        spline.n,
        costs=[acceleration_feature(spline, 2 * P)],
        equalities=[
            configuration_feature(spline, 0.0, first),
            configuration_feature(spline, T, last),
            TaskSpaceFeature(spline, fk, [0.45 * T], target, fk_hessian=fk_hessian),
        ],
    )
    return problem, w0


@pytest.mark.slow
def test_iterations_do_not_grow_with_the_number_of_knots(arm):
    iterations, costs = {}, {}
    for P in (150, 1500):
        problem, w0 = benchmark_problem(*arm, P)
        result = solve(problem, w0, config=SQP)
        assert result.converged and result.outer_iterations == 1, result.status
        iterations[P], costs[P] = result.iterations, result.cost
    assert iterations[1500] <= 2 * iterations[150], iterations
    assert costs[1500] == pytest.approx(10 * costs[150], rel=0.01)  # J ~ P at fixed geometry (K = 2 P)


def _scipy_before(version: str) -> bool:
    import scipy

    return tuple(int(p) for p in scipy.__version__.split(".")[:2]) < tuple(int(p) for p in version.split("."))


@pytest.mark.parametrize("radius", [np.inf, 1.6])
def test_condensation_and_one_band_factorization_give_the_same_steps(reaching, monkeypatch, radius):
    """The KKT steps condensed on the contact window (corl.trajectory.solver.condense) and those of
    one banded Cholesky of the whole KKT Hessian are the same steps: same iterates to rounding."""
    import corl.trajectory.solver.condense as condense
    from corl.trajectory.solver.kkt import KKTSystem

    _, problem, w0 = reaching(P=20)
    used = []
    original = KKTSystem.__init__

    def spy(self, *args, **kwargs):
        original(self, *args, **kwargs)
        used.append(self.cond is not None)

    monkeypatch.setattr(KKTSystem, "__init__", spy)
    condensed = solve(problem, w0, radius=radius, config=SQP)
    assert all(used) and condensed.converged, condensed.status
    monkeypatch.setattr(condense, "_MAX_WINDOW", 0)  # no window qualifies: the direct factorization
    used.clear()
    direct = solve(problem, w0, radius=radius, config=SQP)
    assert not any(used) and direct.converged
    assert direct.iterations == condensed.iterations
    scale = np.abs(direct.w).max()
    np.testing.assert_allclose(condensed.w, direct.w, rtol=0, atol=1e-8 * scale)
    assert condensed.cost == pytest.approx(direct.cost, rel=1e-10)
    np.testing.assert_allclose(condensed.multipliers, direct.multipliers, rtol=1e-6, atol=1e-9 * np.abs(direct.multipliers).max())
    if np.isfinite(radius):
        assert any(record.damping > 0.0 for record in condensed.history)  # the ball was active on some step
