"""Tests of the phase optimization (Eq. 10) and the re-fit of a re-timed path (with Eq. 18)."""

from __future__ import annotations

import numpy as np
import pytest

from corl.errors import InputError
from corl.trajectory.bspline import BSpline
from corl.trajectory.features import TrajectoryProblem, acceleration_feature, configuration_feature
from corl.trajectory.phase import (
    PhaseConfig,
    optimize_phase,
    phase_cost,
    retime,
)

SPLINE = BSpline(20, 2, duration=1.0)
CONFIG = PhaseConfig(num_steps=50, radius=0.2)


def badly_timed():
    """Half circle traversed with speed growing linearly (s = t^2): smooth path, poor timing."""
    t = np.linspace(0.0, 1.0, 200)
    s = t**2
    return SPLINE.fit(t, np.stack([np.cos(np.pi * s), np.sin(np.pi * s)], axis=1))


def distance_to_path(points, w):
    dense = SPLINE.positions(w, np.linspace(0.0, 1.0, 4000))
    return np.sqrt(((points[:, None, :] - dense[None]) ** 2).sum(-1)).min(axis=1).max()


def test_phase_step_lowers_eq10_inside_the_trust_region_and_keeps_p_monotone():
    w = badly_timed()
    identity = np.linspace(0.0, 1.0, 51)
    result = optimize_phase(SPLINE, w, config=CONFIG)
    assert result.cost_before == pytest.approx(phase_cost(SPLINE, w, identity, CONFIG))
    assert result.cost_after < 0.9 * result.cost_before
    assert result.cost_after == pytest.approx(phase_cost(SPLINE, w, result.p, CONFIG))
    assert result.p[0] == 0.0 and result.p[-1] == 1.0
    assert np.diff(result.p).min() > 0
    assert result.step_norm <= CONFIG.radius * (1 + 1e-9)
    for record in result.solve.history:  # every inner iterate inside the ball
        assert np.linalg.norm(record.w - identity[1:-1]) <= CONFIG.radius * (1 + 1e-9)


def test_retimed_path_keeps_the_geometry():
    w = badly_timed()
    result = optimize_phase(SPLINE, w, config=CONFIG)
    retimed = retime(SPLINE, w, result.p, config=CONFIG)
    samples = SPLINE.positions(retimed.w, np.linspace(0.0, 1.0, 300))
    assert distance_to_path(samples, w) < 5e-3  # on a path of length pi
    assert retimed.fit_error < 5e-3
    # the timing did change: the re-timed trajectory is not the old one
    assert np.abs(samples - SPLINE.positions(w, np.linspace(0.0, 1.0, 300))).max() > 0.05


def test_pinned_times_keep_their_phase():
    w = badly_timed()
    result = optimize_phase(SPLINE, w, config=CONFIG, pinned_times=[0.4])
    assert result.p[20] == pytest.approx(0.4)
    assert result.cost_after < result.cost_before


def test_monotone_repair_and_bad_inputs():
    with pytest.raises(InputError, match="min_increment"):
        PhaseConfig(min_increment=1.5)
    with pytest.raises(InputError, match="p_start"):
        optimize_phase(SPLINE, badly_timed(), np.linspace(0.1, 1, 51), config=CONFIG)


def test_retime_projects_a_trajectory_problem_on_the_sqp_path():
    w0 = badly_timed()
    ends = SPLINE.positions(w0, [0.0, 0.5, 1.0])
    problem = TrajectoryProblem(SPLINE.n, [acceleration_feature(SPLINE, 40)],
                                [configuration_feature(SPLINE, t, q) for t, q in zip((0.0, 0.5, 1.0), ends)])
    phase = optimize_phase(SPLINE, w0, config=CONFIG)
    structured = retime(SPLINE, w0, phase.p, equalities=problem, config=CONFIG)
    plain = retime(SPLINE, w0, phase.p, equalities=problem.equalities, config=CONFIG)  # a callable: the manifold path
    assert "SQP" in structured.projection.status and "SQP" not in plain.projection.status
    assert structured.h_fit > 1e-3 and structured.h_after < 1e-8 and plain.h_after < 1e-8
    moved = np.linalg.norm(structured.w - structured.w_fit)
    assert np.linalg.norm(structured.w - plain.w) <= 1e-6 * moved  # Eq. 18 is convex here: one answer


def test_banded_gauss_newton_model_is_that_of_the_sparse_jacobian():
    """gauss_newton_band gives 2 J^T J (band storage) and 2 J^T r of residuals()'s J, pinned phases and
    active monotonicity hinges included."""
    from corl.trajectory.phase import PhaseProblem

    problem = PhaseProblem(SPLINE, badly_timed(), CONFIG, pinned_times=[0.4, 0.42])
    rng = np.random.default_rng(0)
    p_free = problem.identity[problem.free] + 0.012 * rng.normal(size=problem.free.size)
    assert np.any(np.diff(problem.full(p_free)) < problem.delta)  # some hinges are active
    r, J = problem.residuals(p_free)
    r_band, g, H = problem.gauss_newton_band(p_free)
    np.testing.assert_allclose(r_band, r, rtol=1e-13, atol=1e-13 * np.abs(r).max())
    dense = 2.0 * (J.T @ J).toarray()
    assert H.bandwidth == 2
    np.testing.assert_allclose(H.toarray(), dense, rtol=0, atol=1e-13 * np.abs(dense).max())
    np.testing.assert_allclose(g, 2.0 * J.T @ r, rtol=0, atol=1e-13 * np.abs(g).max())


def test_phase_steps_run_on_banded_factors(monkeypatch):
    """optimize_phase takes its Gauss-Newton model in band storage (no sparse Jacobian per iterate) and
    reaches the Eq. 10 cost of the sparse path."""
    import corl.trajectory.solver.linalg as linalg
    from corl.trajectory.phase import PhaseProblem
    from corl.trajectory.solver.banded import BandedSPD

    factored = []
    original = linalg.factorize_spd

    def spy(H, *args, **kwargs):
        factored.append(type(H))
        return original(H, *args, **kwargs)

    monkeypatch.setattr(linalg, "factorize_spd", spy)
    banded = optimize_phase(SPLINE, badly_timed(), config=CONFIG)
    assert factored and set(factored) == {BandedSPD}
    monkeypatch.setattr(PhaseProblem, "gauss_newton_band", None)  # the sparse path of the same iteration
    sparse = optimize_phase(SPLINE, badly_timed(), config=CONFIG)
    assert banded.cost_after == pytest.approx(sparse.cost_after, rel=1e-9)
    np.testing.assert_allclose(banded.p, sparse.p, atol=1e-7)
