"""The example context families (examples/lever_arm.py, kit_plunger.py, heldout_wipe.py): each scene's
demonstration succeeds across the box, failures are reachable, and best_return is the best of a
brute-force check."""

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from panda import needs_panda  # noqa: E402


@pytest.fixture(autouse=True)
def fresh_cache(tmp_path, monkeypatch):
    """best_return computes afresh here, never from a cache of an earlier version."""
    monkeypatch.setenv("CORL_EXAMPLES_CACHE", str(tmp_path / "cache"))


def _corners(bounds):
    return [np.array(c) for c in itertools.product(*zip(bounds.lower, bounds.upper))]


def _brute_force(task, axes):
    """The best return over a grid, each point's motion solved from the demonstration (no continuation)."""
    from examples.ground_truth import motion_at

    demo = task.demonstration()
    best = -np.inf
    for theta in itertools.product(*axes):
        w = motion_at(task, theta, demo.w)
        outcome = None if w is None else task.rollout(w)
        if outcome is not None and outcome.success:
            best = max(best, outcome.return_)
    return best


def _check_truth(task, axes, tol):
    from examples.ground_truth import best_return

    demo = task.demonstration()
    R_demo = task.rollout(demo.w).return_
    R_best = task.best_return()
    truth = best_return(task, demo.w, task_grid(task))  # from the cache: where, and how many points
    assert R_best == truth["best_return"]  # the second call reads the cache
    assert truth["best_return"] >= R_demo
    brute = _brute_force(task, axes)
    assert brute <= truth["best_return"] + 1e-6 * max(1.0, abs(brute))  # nothing on the check's grid beats it
    assert brute >= truth["best_return"] - tol  # and the check's grid comes close to it
    return truth


def task_grid(task):
    import importlib

    return importlib.import_module(type(task).__module__).GRID


def test_lever_arm_demonstration_across_the_box_and_failures():
    from examples.lever_arm import make_task
    from examples.ground_truth import motion_at

    base = make_task()
    for c in [base.context] + _corners(base.context_bounds):
        task = base.with_context(c)
        demo = task.demonstration()
        assert np.allclose(demo.theta, [0.10, 0.30], atol=1e-3)
        assert task.rollout(demo.w).success, c
    # too far up the lever (slips off its end, or misses it), too shallow (no click), too close in on a stiff lever (too hard)
    stiff = base.with_context([0.0, 0.0, 2.4])
    for theta, why in (([0.215, 0.35], "slipped off the lever"), ([0.25, 0.35], "never touched the lever"), ([0.15, 0.22], "did not click"),
                       ([0.05, 0.35], "pushed too hard")):
        outcome = stiff.rollout(motion_at(stiff, theta, stiff.demonstration().w))
        assert not outcome.success and outcome.info["why"] == why
    # theta*(c) moves with the context: a stiffer spring is pushed farther out (coarse grids)
    from examples.ground_truth import best_return

    soft = base.with_context([0.0, 0.0, 0.8])
    r_soft = best_return(soft, soft.demonstration().w, (9, 4), fine=3)["theta"][0]
    r_stiff = best_return(stiff, stiff.demonstration().w, (9, 4), fine=3)["theta"][0]
    assert r_stiff > r_soft + 0.04


@pytest.mark.slow
def test_lever_arm_best_return_beats_a_brute_force_grid():
    from examples.lever_arm import make_task

    task = make_task([0.03, -0.1, 2.0])
    truth = _check_truth(task, [np.linspace(0.1, 0.2, 5), np.linspace(0.28, 0.44, 4)], tol=0.03)
    assert 0.12 < truth["theta"][0] < 0.21  # a stiff lever is pushed far out


@pytest.mark.slow
def test_heldout_wipe_demonstration_and_best_return():
    from examples.heldout_wipe import make_task
    from examples.ground_truth import motion_at

    base = make_task()
    for c in _corners(base.context_bounds):
        task = base.with_context(c)
        assert task.rollout(task.demonstration().w).success, c
    for theta, why in (([-0.003, 0.1], "lost the wall"), ([0.004, 0.215], "slid over the wall's end")):
        outcome = base.rollout(motion_at(base, theta, base.demonstration().w))
        assert not outcome.success and outcome.info["why"] == why
    _check_truth(base, [np.linspace(0.004, 0.012, 5), np.linspace(0.1, 0.18, 4)], tol=0.05)


@needs_panda
@pytest.mark.slow
def test_kit_plunger_demonstration_failures_and_best_return():
    from examples.kit_plunger import make_task
    from examples.ground_truth import motion_at

    base = make_task()
    for c in ([0.05, 0.05, 450.0], [-0.05, -0.05, 150.0]):
        task = base.with_context(c)
        assert task.rollout(task.demonstration().w).success, c
    demo = base.demonstration()
    for theta, why in (([0.004], "did not click"), ([0.024], "pressed against the housing")):
        outcome = base.rollout(motion_at(base, theta, demo.w))
        assert not outcome.success and outcome.info["why"] == why
    truth = _check_truth(base, [np.linspace(0.012, 0.02, 5)], tol=0.03)
    assert 0.012 < truth["theta"][0] < 0.02
