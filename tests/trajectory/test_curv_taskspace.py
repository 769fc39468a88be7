"""TaskSpaceFeature takes its curvature from ``fk.hessian`` when fk offers one (as the features of
corl.mujoco do), and from forward differences of the Jacobian otherwise."""

import numpy as np
import pytest

from corl.errors import InputError
from corl.trajectory.bspline import BSpline
from corl.trajectory.taskspace import TaskSpaceFeature

SPLINE = BSpline(12, 7, duration=2.0)
TIMES = [0.5, 0.9, 1.4]


class CountingFeature:
    """``fk`` with a ``hessian`` method (the duck type of corl.mujoco.features.Feature) that counts calls."""

    def __init__(self, fk, hessian):
        self._fk, self._hessian = fk, hessian
        self.calls = {"fk": 0, "hessian": 0}

    def __call__(self, q):
        self.calls["fk"] += 1
        return self._fk(q)

    def hessian(self, q):
        self.calls["hessian"] += 1
        return self._hessian(q)


def problem_data(arm, seed=0):
    fk, _ = arm
    rng = np.random.default_rng(seed)
    w = rng.normal(scale=0.4, size=SPLINE.n)
    nu = rng.normal(size=3 * len(TIMES))
    targets = np.array([fk(q)[0] for q in SPLINE.positions(w, TIMES)]) + 0.01
    return w, nu, targets


def dense(blocks, n):
    C = np.zeros((n, n))
    for cols, block in blocks:
        C[np.ix_(cols, cols)] += block
    return C


def test_picks_up_fk_hessian(arm):
    fk, hessian = arm
    w, nu, targets = problem_data(arm)
    feature = CountingFeature(fk, hessian)
    auto = TaskSpaceFeature(SPLINE, feature, TIMES, targets)
    assert auto.fk_hessian == feature.hessian
    explicit = TaskSpaceFeature(SPLINE, fk, TIMES, targets, fk_hessian=hessian)
    C = dense(auto.curvature(w, nu), SPLINE.n)
    np.testing.assert_array_equal(C, dense(explicit.curvature(w, nu), SPLINE.n))
    assert feature.calls == {"fk": 0, "hessian": len(TIMES)}  # no forward kinematics for the curvature
    # the forward differences (Q + 1 calls of fk per time) agree to their truncation error
    differences = TaskSpaceFeature(SPLINE, fk, TIMES, targets)
    C_fd = dense(differences.curvature(w, nu), SPLINE.n)
    assert np.abs(C - C_fd).max() < 1e-6 * np.abs(C).max()
    np.testing.assert_array_equal(C, C.T)


def test_explicit_hessian_wins(arm):
    fk, hessian = arm
    w, nu, targets = problem_data(arm, seed=1)
    feature = CountingFeature(fk, lambda q: np.full((3, 7, 7), np.nan))
    f = TaskSpaceFeature(SPLINE, feature, TIMES, targets, fk_hessian=hessian)
    assert np.all(np.isfinite(dense(f.curvature(w, nu), SPLINE.n)))
    assert feature.calls["hessian"] == 0


def test_non_callable_hessian_attribute_is_ignored(arm):
    fk, _ = arm

    def plain(q):
        return fk(q)

    plain.hessian = "not a function"
    w, nu, targets = problem_data(arm)
    f = TaskSpaceFeature(SPLINE, plain, TIMES, targets)
    assert f.fk_hessian is None
    assert len(f.curvature(w, nu)) == len(TIMES)
    with pytest.raises(InputError, match="fk_hessian must be callable"):
        TaskSpaceFeature(SPLINE, fk, TIMES, targets, fk_hessian="nope")
