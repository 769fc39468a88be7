"""Several trials out at once (max_pending = K > 1) in the ask/tell base and in CORL's SafeBOOptimizer."""

import numpy as np
import pytest

from corl.errors import InputError, StateError
from corl.optimizers.pending import P_PENDING, PENDING_RADIUS
from corl.optimizers.safe import SafeBOOptimizer
from corl.problem import Bounds, Outcome

BOX = Bounds(np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
CENTRE, OPTIMUM = np.array([0.2, 0.1]), np.array([0.9, 0.6])


def disc(x):
    """Succeeds inside a disc of radius 0.35; R peaks at OPTIMUM, beyond its edge (the search maps the edge)."""
    ok = bool(np.linalg.norm(x - CENTRE) < 0.35)
    return Outcome(ok, float(-np.sum((x - OPTIMUM) ** 2)) if ok else None)


def fleet(k, budget=14, seed=0, order=0):
    """Run with k trials out; tell the ``order``-th oldest pending first. Returns (optimizer, batches)."""
    opt = SafeBOOptimizer(BOX, max_evals=budget, seed=seed, start=np.zeros(2))
    opt.max_pending = k
    opt.recheck_failures = False  # as inside Algorithm 1: a failed point is never asked again
    out, batches = [], []
    while not opt.done:
        while opt.ready:
            x = opt.ask()
            for p in out:  # never the same motion as a trial still out
                assert not np.all(np.abs(x - p) <= opt.answer_tolerance * BOX.width)
            out.append(x)
        assert out, "not done and not ready with nothing pending"
        batches.append(np.array(out))
        x = out.pop(min(order, len(out) - 1))
        opt.tell(x, disc(x))
    return opt, batches


def test_the_start_goes_out_alone():
    opt = SafeBOOptimizer(BOX, max_evals=10, seed=0, start=np.zeros(2))
    opt.max_pending = 4
    assert np.array_equal(opt.ask(), np.zeros(2))
    assert not opt.ready and not opt.done  # a safe method proposes nothing before a known success
    with pytest.raises(StateError, match="pending"):
        opt.ask()
    opt.tell(np.zeros(2), disc(np.zeros(2)))
    assert opt.ready


def test_four_out_are_apart_and_each_safe_under_the_told_data():
    opt = SafeBOOptimizer(BOX, max_evals=30, seed=1, start=np.zeros(2))
    opt.max_pending = 4
    opt.tell(opt.ask(), disc(np.zeros(2)))
    for theta in ([0.3, 0.0], [0.0, 0.3], [-0.3, 0.0]):
        opt.tell(np.array(theta), disc(np.array(theta)))
    out = [opt.ask() for _ in range(4)]
    assert not opt.ready and len(opt.pending_) == 4
    with pytest.raises(StateError):
        opt.ask()
    _, classifier = opt._fitted_models()  # g_S on the told data only: no fantasy of a pending success
    p = classifier.predict_proba(np.array(out))
    assert np.all(p >= opt.seib.p_band), p
    assert np.sum(p < P_PENDING) <= 1, p  # at most one out whose success g_S doubts
    radius = PENDING_RADIUS * classifier.kernel_.lengthscales
    for i in range(4):
        for j in range(i):
            assert np.linalg.norm((out[i] - out[j]) / radius) >= 1.0 - 1e-9


def test_tells_in_any_order_and_each_once():
    opt = SafeBOOptimizer(BOX, max_evals=30, seed=1, start=np.zeros(2))
    opt.max_pending = 3
    opt.tell(opt.ask(), disc(np.zeros(2)))
    for theta in ([0.3, 0.0], [0.0, 0.3], [-0.3, 0.0]):
        opt.tell(np.array(theta), disc(np.array(theta)))
    out = [opt.ask() for _ in range(3)]
    opt.tell(out[2], disc(out[2]))
    with pytest.raises(StateError, match="told"):
        opt.tell(out[2], disc(out[2]))
    opt.tell(out[0], disc(out[0]))
    assert len(opt.pending_) == 1 and np.allclose(opt.pending_[0], out[1])
    assert opt.n_evals == 6
    opt.tell(out[1], disc(out[1]))
    assert len(opt.pending_) == 0 and opt.ready


@pytest.mark.parametrize("order", [3])  # told oldest first (0, 1, 2), the fleet meets no failure on this disc
def test_a_fleet_never_repeats_a_known_failure_and_keeps_the_budget(order):
    opt, batches = fleet(4, budget=28, order=order)
    assert opt.n_evals <= 28 and max(len(b) for b in batches) >= 3 and opt.stop_reason is not None
    assert (~opt.success_).sum() >= 1  # the disc's edge was met: the check below means something
    for i in np.flatnonzero(~opt.success_):
        later = opt.X_[i + 1:]
        assert not np.any(np.all(np.abs(later - opt.X_[i]) <= opt.answer_tolerance * BOX.width, axis=1))
    best = opt.best
    assert best is not None and disc(best[0]).success


def test_one_at_a_time_is_unchanged_and_the_setting_is_checked():
    one = SafeBOOptimizer(BOX, max_evals=8, seed=2, start=np.zeros(2))
    assert one.max_pending == 1 and np.array_equal(one.ask(), one.ask())  # the same point until it is told
    with pytest.raises(StateError, match="before the first ask"):
        one.max_pending = 2
    for bad in (0, 1.5, True, "2"):
        with pytest.raises(InputError, match="max_pending"):
            SafeBOOptimizer(BOX, max_evals=8, start=np.zeros(2)).max_pending = bad
