"""The solver (Eq. 8) and projection (Eq. 18) on B-spline trajectory problems with a contact constraint."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import minimize

from corl.trajectory.solver import SolverConfig, project, solve
from corl.trajectory.solver.banded import BandedSPD
from corl.trajectory.solver.model import evaluate_problem, gauss_newton


@pytest.mark.parametrize("method", ["al", "sqp"])
def test_banded_path_is_used_and_the_result_satisfies_kkt_and_matches_slsqp(reaching, method):
    spline, problem, w0 = reaching()
    assert spline.n == 98
    pt = evaluate_problem(problem, w0)
    _, H = gauss_newton(pt, np.zeros(17), 1.0)
    assert isinstance(H, BandedSPD) and H.bandwidth < 35
    result = solve(problem, w0, config=replace(SolverConfig.trajectory(), method=method))
    assert result.converged, result.status
    assert ("SQP" in result.status) == (method == "sqp")
    h, Jh = problem.equalities(result.w)
    r, Jr = problem.residuals(result.w)
    assert np.abs(h).max() < 1e-8
    # KKT of Eq. 8 (ball inactive): grad J + Jh^T nu = 0 for some nu
    grad = 2 * Jr.T @ r
    nu = np.linalg.lstsq(Jh.toarray().T, -grad, rcond=None)[0]
    assert np.linalg.norm(grad + Jh.T @ nu) < 1e-6 * np.linalg.norm(grad)
    np.testing.assert_allclose(result.multipliers, nu, rtol=1e-4, atol=1e-6 * np.abs(nu).max())
    reference = minimize(
        problem.cost,
        w0,
        jac=lambda w: 2 * problem.residuals(w)[1].T @ problem.residuals(w)[0],
        constraints=[{"type": "eq", "fun": lambda w: problem.equalities(w)[0], "jac": lambda w: problem.equalities(w)[1].toarray()}],
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert reference.success
    assert result.cost == pytest.approx(reference.fun, rel=1e-6)
    np.testing.assert_allclose(result.w, reference.x, atol=1e-4)


def test_history_reports_every_step_and_the_trust_region_holds(reaching):
    spline, problem, w0 = reaching()
    radius = 0.2
    result = solve(problem, w0, radius=radius, config=SolverConfig.trajectory())
    assert result.trust_region_active
    assert len(result.history) >= 3
    for record in result.history:
        assert np.linalg.norm(record.w - w0) <= radius * (1 + 1e-9)
        assert np.isfinite([record.cost, record.constraint_error, record.step_norm]).all()
    assert result.history[-1].constraint_error < result.history[0].constraint_error


def test_project_works_with_sparse_spline_constraints_at_n_1200(reaching):
    spline, problem, w0 = reaching(P=172)
    assert spline.n == 1204
    start = time.perf_counter()
    result = project(problem, w0)
    elapsed = time.perf_counter() - start
    assert result.converged, result.status
    assert result.constraint_error < 1e-6
    # Eq. 18 moves only what the constraints touch: the end control points and those active at t_c
    changed = np.unique(np.flatnonzero(np.abs(result.w - w0) > 1e-9) // 7)
    active = np.flatnonzero(spline.basis([0.9]).toarray()[0])
    assert set(changed) <= {0, spline.num_control_points - 1} | set(active.tolist())
    assert set(active.tolist()) <= set(changed)
    assert elapsed < 5.0  # generous; the benchmark reports the real time
