"""SEIB (corl.acquisition.safe_ei): EI closed form, the safety gate, the return gate, no stall."""

import numpy as np
import pytest

from corl.acquisition.safe_ei import SEIB, SEIBConfig, SEIBTuning, expected_improvement
from corl.errors import InputError
from corl.gp import GPClassifier, GPRegression, SquaredExponential


def test_expected_improvement_matches_numerical_integration():
    from scipy import integrate
    from scipy.stats import norm

    for mu, var, thr in [(0.0, 1.0, 0.5), (2.0, 0.25, 1.0), (-1.0, 4.0, 3.0)]:
        sd = np.sqrt(var)
        ref, _ = integrate.quad(lambda r: (r - thr) * norm.pdf(r, mu, sd), thr, mu + 12 * sd)
        got = expected_improvement(np.array([mu]), np.array([var]), thr)[0]
        assert got == pytest.approx(ref, rel=1e-7, abs=1e-12)
    assert np.all(expected_improvement(np.zeros(3), np.zeros(3), 1.0) >= 0.0)  # var floored, never negative


def _models():
    """1-D: successes on [0.3, 0.6] with R rising to the right, failures at 0 and 1."""
    X = np.array([0.0, 0.3, 0.4, 0.5, 0.6, 1.0])[:, None]
    s = np.array([False, True, True, True, True, False])
    r = np.array([np.nan, 0.0, 1.0, 2.0, 3.0, np.nan])
    clf = GPClassifier(SquaredExponential(0.08, 10.0), prior_mean=-7.0).fit(X, s)
    reg = GPRegression(SquaredExponential(0.15, 2.0), 0.01, prior_mean=1.5).fit(X[s], r[s])
    return reg, clf


def test_value_is_zero_wherever_success_is_unlikely():
    reg, clf = _models()
    acq = SEIB(reg, clf, best_return=3.0, scale=1.1)
    grid = np.linspace(0, 1, 1001)[:, None]
    parts = acq.parts(grid)
    assert np.all(parts["value"][parts["proba"] < acq.config.p_band] == 0.0)
    assert np.any(parts["value"] > 0)


def test_boundary_is_explored_only_where_the_return_may_improve():
    reg, clf = _models()
    acq = SEIB(reg, clf, best_return=3.0, scale=1.1, config=SEIBConfig(_tuning=SEIBTuning(boundary_weight=1.0)))
    grid = np.linspace(0, 1, 2001)[:, None]
    parts = acq.parts(grid)
    band = parts["band"]
    left, right = band & (grid[:, 0] < 0.45), band & (grid[:, 0] > 0.45)
    assert np.any(left) and np.any(right)  # the model has a boundary on both sides
    assert np.all(parts["value"][left] < 1e-6)  # low returns on the left: that edge is not mapped
    assert np.max(parts["value"][right]) > 0.05  # rising returns on the right: its edge is
    assert 0.45 < grid[np.argmax(parts["value"]), 0] < 0.9


def test_does_not_stall_beside_the_best_point():
    reg, clf = _models()
    acq = SEIB(reg, clf, best_return=3.0, scale=1.1)
    grid = np.linspace(0, 1, 2001)[:, None]
    values = acq(grid)
    at_best = acq(np.array([[0.6]]))[0]
    assert at_best < 0.01 * values.max()  # the margin xi leaves nothing to gain at the best point


def test_band_rel_raises_the_band_point_gate_s_margin_and_nothing_else():
    reg, clf = _models()
    grid = np.linspace(0, 1, 2001)[:, None]
    base = SEIB(reg, clf, best_return=3.0, scale=1.1, config=SEIBConfig(_tuning=SEIBTuning(boundary_weight=1.0)))
    same = SEIB(reg, clf, best_return=3.0, scale=1.1, config=SEIBConfig(band_rel=0.005, _tuning=SEIBTuning(boundary_weight=1.0)))
    np.testing.assert_array_equal(same(grid), base(grid))  # below xi (0.01): xi is the margin, as before
    parts = base.parts(grid)
    band = parts["band"] & parts["ucb_gate"]
    mu, var = reg.predict(grid[band])
    ucb = mu + 2.0 * np.sqrt(var)
    u = np.sort(ucb)  # a margin that shuts about half of the open band points, midway between two
    rel = float(0.5 * (u[len(u) // 2 - 1] + u[len(u) // 2]) - 3.0) / 1.1  # of them (no point within rounding of it)
    assert rel > 0.01
    strict = SEIB(reg, clf, best_return=3.0, scale=1.1, config=SEIBConfig(band_rel=rel, _tuning=SEIBTuning(boundary_weight=1.0))).parts(grid)
    kept = strict["ucb_gate"][band]
    assert 0 < kept.sum() < band.sum()
    np.testing.assert_array_equal(kept, ucb > 3.0 + rel * 1.1)  # the gate is UCB_R > R^+ + band_rel * scale
    assert np.all(strict["value"][band][~kept] == 0.0)  # a shut band point is not proposed
    inner = parts["inner"]
    np.testing.assert_array_equal(strict["value"][inner], parts["value"][inner])  # the inner EI is untouched
    shut = SEIB(reg, clf, best_return=3.0, scale=1.1, config=SEIBConfig(band_rel=float("inf"))).parts(grid)
    assert not np.any(shut["value"][shut["band"]])  # inf: the edge is never mapped at the band points
    for bad in (-0.1, float("nan"), None, "0.05", True):
        with pytest.raises(InputError, match="band_rel"):
            SEIBConfig(band_rel=bad)
    assert SEIBConfig(band_rel=np.int64(1)).band_rel == 1  # a NumPy number is a number


def test_without_a_return_model_only_the_boundary_acts():
    _, clf = _models()
    acq = SEIB(None, clf, best_return=0.0, scale=1.0)
    parts = acq.parts(np.linspace(0, 1, 501)[:, None])
    assert np.all(parts["value"][parts["inner"]] == 0.0)
    assert np.all(parts["value"][~parts["band"]] == 0.0)


def test_bad_settings_are_refused():
    with pytest.raises(InputError, match="p_band"):
        SEIBConfig(p_band=0.8)
    reg, clf = _models()
    with pytest.raises(InputError, match="scale"):
        SEIB(reg, clf, 1.0, scale=0.0)


def _local_peak_models():
    """1-D on [0, 1]: successes clustered at a local peak x = 0.6, one failure at 0.85 (right).

    The return GP (l = 0.1, sf = 1, prior mean 0) is sure R is lower at the band points beside
    the cluster, but a length scale further left, where nothing was tried, R may be up to 2.
    """
    X = np.array([0.5, 0.55, 0.6, 0.65, 0.7, 0.85])[:, None]
    s = np.array([True, True, True, True, True, False])
    r = np.array([0.6, 0.9, 1.0, 0.9, 0.6, np.nan])
    clf = GPClassifier(SquaredExponential(0.1, 10.0), prior_mean=-7.0).fit(X, s)
    reg = GPRegression(SquaredExponential(0.1, 1.0), 0.01, prior_mean=0.0).fit(X[s], r[s])
    return reg, clf


def test_looking_beyond_the_band_opens_the_unexplored_side_only():
    reg, clf = _local_peak_models()
    grid = np.linspace(0, 1, 2001)[:, None]
    point = SEIB(reg, clf, best_return=1.0, scale=0.16).parts(grid)
    band = point["band"]
    left, right = band & (grid[:, 0] < 0.6), band & (grid[:, 0] > 0.6)
    assert np.any(left) and np.any(right)
    assert np.max(point["value"][band]) < 1e-6  # the band-point gate closes both sides: a stop
    beyond = SEIB(reg, clf, best_return=1.0, scale=0.16, beyond=True, box=([0.0], [1.0])).parts(grid)
    outer = left & (grid[:, 0] < np.median(grid[left, 0]))  # the outer half of the left band
    assert np.all(beyond["ucb_gate"][outer]) and np.min(beyond["value"][outer]) > 0.01  # unexplored: go on
    assert not np.any(beyond["ucb_gate"][right])  # the ray to the right ends at the failure at 0.85
    assert np.all(beyond["value"][~band & ~beyond["inner"]] == 0.0)  # still only band points proposed


def test_looking_beyond_needs_a_real_gain_and_stays_in_the_box():
    reg, clf = _local_peak_models()
    grid = np.linspace(0, 1, 2001)[:, None]
    band = SEIB(reg, clf, 1.0, 0.16).parts(grid)["band"] & (grid[:, 0] < 0.6)
    # R^+ above the prior UCB (0 + 2 * 1) by the margin: nothing beyond can beat it
    high = SEIB(reg, clf, 1.0, 0.16, SEIBConfig(_tuning=SEIBTuning(beyond_rel=7.0)), beyond=True).parts(grid)
    assert not np.any(high["ucb_gate"][band])
    # a box ending at the band leaves only the band point itself, where the model is sure R is lower
    lo = float(grid[band, 0].min())
    boxed = SEIB(reg, clf, 1.0, 0.16, beyond=True, box=([lo - 1e-9], [1.0])).parts(grid)
    assert not boxed["ucb_gate"][np.flatnonzero(band)[0]]


def test_outward_normal_points_away_from_the_safe_set():
    reg, clf = _local_peak_models()
    acq = SEIB(reg, clf, 1.0, 0.16)
    n = acq.outward(np.array([[0.4], [0.8]]))
    np.testing.assert_allclose(n, [[-1.0], [1.0]])


def test_beyond_settings_are_checked():
    with pytest.raises(InputError, match="beyond_rel"):
        SEIBTuning(beyond_rel=-1.0)
    with pytest.raises(InputError, match="reach"):
        SEIBTuning(reach=())


def _valley_models(fail_left: bool = False):
    """1-D on [0, 1]: a local peak at 0.6 and its left slope sampled down to R ~ 0 at 0.3.

    One length scale (0.1) left of the band, g_R has the slope's zeros beside it and is sure R is
    low: the look beyond closes. Four length scales out it reverts to its prior (mean 0, sf 1), and
    there R may beat the best. A failure at 0.85 closes the right side; ``fail_left`` adds one at
    0.22, just past the left band.
    """
    x = [0.3, 0.35, 0.4, 0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.85] + ([0.22] if fail_left else [])
    X = np.array(x)[:, None]
    s = np.array([True] * 9 + [False] * (len(x) - 9))
    r = np.where(s, np.exp(-(X[:, 0] - 0.6) ** 2 / 0.01), np.nan)
    clf = GPClassifier(SquaredExponential(0.05, 10.0), prior_mean=-7.0).fit(X, s)
    reg = GPRegression(SquaredExponential(0.1, 1.0), 0.01, prior_mean=0.0).fit(X[s], r[s])
    return reg, clf, float(np.std(r[s]))


def test_looking_far_crosses_a_valley_the_look_beyond_cannot():
    reg, clf, scale = _valley_models()
    grid = np.linspace(0, 1, 2001)[:, None]
    kw = dict(box=([0.0], [1.0]))
    beyond = SEIB(reg, clf, 1.0, scale, beyond=True, **kw).parts(grid)
    far = SEIB(reg, clf, 1.0, scale, beyond=True, far=True, **kw).parts(grid)
    band = beyond["band"]
    left, right = band & (grid[:, 0] < 0.5), band & (grid[:, 0] > 0.5)
    assert np.any(left) and np.any(right)
    assert not np.any(beyond["ucb_gate"][band])  # one length scale out: still the valley
    assert np.any(far["ucb_gate"][left]) and np.max(far["value"][left]) > 0.01  # four out: the prior
    assert not np.any(far["ucb_gate"][right])  # the failure at 0.85 closes the right side
    assert np.all(far["value"][~band & ~far["inner"]] == 0.0)  # still only band points proposed
    none = SEIB(reg, clf, 1.0, scale, SEIBConfig(_tuning=SEIBTuning(far_reach=(0.0, 0.5, 1.0))), beyond=True, far=True, **kw)
    assert not np.any(none.parts(grid)["ucb_gate"][band])  # the distance, not the margin, opens it


def test_looking_far_starts_only_from_band_points_clear_of_failures():
    reg, clf, scale = _valley_models(fail_left=True)
    grid = np.linspace(0, 1, 2001)[:, None]
    far = SEIB(reg, clf, 1.0, scale, beyond=True, far=True, box=([0.0], [1.0])).parts(grid)
    assert np.any(far["band"] & (grid[:, 0] < 0.5))
    assert not np.any(far["ucb_gate"])  # the left band lies within 2 g_S length scales of 0.22
    wide = SEIB(reg, clf, 1.0, scale, SEIBConfig(_tuning=SEIBTuning(far_open=0.5)), beyond=True, far=True, box=([0.0], [1.0]))
    opened = grid[wide.parts(grid)["ucb_gate"], 0]
    assert opened.size and np.all(opened > 0.5)  # a smaller far_open lets the right side nearer 0.85 open,
    # while the left ray still ends at the failure just past the band


def test_a_failure_behind_the_band_point_does_not_block_its_far_ray():
    """1-D: one failure at 0.44, just left of three successes; the right band lies within
    ``far_open`` g_S length scales of it, but on the far side of the safe interval."""
    X = np.array([0.5, 0.53, 0.56, 0.44])[:, None]
    s = np.array([True, True, True, False])
    r = np.array([1.0, 0.9, 0.8])  # falling to the right: only the far look may open the right band
    clf = GPClassifier(SquaredExponential(0.1, 10.0), prior_mean=-7.0).fit(X, s)
    reg = GPRegression(SquaredExponential(0.05, 1.0), 0.01, prior_mean=0.0).fit(X[s], r)
    grid = np.linspace(0, 1, 2001)[:, None]
    right = grid[:, 0] > 0.56
    for cfg, opens in [(SEIBConfig(), True), (SEIBConfig(_tuning=SEIBTuning(far_behind=1.0)), False)]:
        parts = SEIB(reg, clf, 1.0, float(np.std(r)), cfg, beyond=True, far=True, box=([0.0], [1.0])).parts(grid)
        band = parts["band"]
        assert np.any(band & right) and np.min(np.abs(grid[band & right, 0] - 0.44)) < 2 * 0.1  # within far_open
        assert bool(np.any(parts["ucb_gate"] & right)) is opens  # far_behind=1: every failure blocks (the old rule)
        assert not np.any(parts["ucb_gate"] & ~right)  # the failure stays ahead of the left band: closed


def test_far_settings_are_checked():
    with pytest.raises(InputError, match="far_reach"):
        SEIBTuning(far_reach=(-1.0,))
    with pytest.raises(InputError, match="far_open"):
        SEIBTuning(far_open=-1.0)
    for bad in (-0.5, float("nan"), float("inf")):  # NaN switched the far look off without a word
        with pytest.raises(InputError, match="far_beta"):
            SEIBConfig(far_beta=bad)
    with pytest.raises(InputError, match="beta"):
        SEIBTuning(beta=float("nan"))
    assert SEIBConfig(far=False).far_reach == ()  # never look far
    for bad in (-1.5, 1.01, float("nan")):
        with pytest.raises(InputError, match="far_behind"):
            SEIBTuning(far_behind=bad)


def test_looking_far_heads_where_the_return_may_be_highest():
    # three successes peaked at 0.25 in [0, 1], no failure: both sides of the band are open looking
    # far, but the left ray ends at the box after about two length scales while the right one
    # reaches four, where g_R has reverted to its prior: the right side promises more and scores more
    X = np.array([0.2, 0.25, 0.3])[:, None]
    r = np.array([0.8, 1.0, 0.8])
    clf = GPClassifier(SquaredExponential(0.05, 10.0), prior_mean=-7.0).fit(X, np.ones(3, dtype=bool))
    reg = GPRegression(SquaredExponential(0.1, 1.0), 0.01, prior_mean=0.0).fit(X, r)
    grid = np.linspace(0, 1, 2001)[:, None]
    scale = float(np.std(r))
    plain = SEIB(reg, clf, 1.0, scale, beyond=True, box=([0.0], [1.0])).parts(grid)
    far = SEIB(reg, clf, 1.0, scale, beyond=True, far=True, box=([0.0], [1.0])).parts(grid)
    left, right = far["band"] & (grid[:, 0] < 0.25), far["band"] & (grid[:, 0] > 0.25)
    assert np.any(far["ucb_gate"][left]) and np.any(far["ucb_gate"][right])
    v_left, v_right = np.max(plain["boundary"][left]), np.max(plain["boundary"][right])
    assert abs(v_left - v_right) < 1e-6 * v_right  # the boundary uncertainty alone cannot tell them apart
    assert np.max(far["value"][right]) > 1.1 * np.max(far["value"][left])


@pytest.mark.parametrize("far_beta", [2.0, 3.0])
def test_far_beta_is_the_ucb_width_on_the_far_ray_and_only_there(far_beta):
    reg, clf, scale = _valley_models()
    grid = np.linspace(0, 1, 2001)[:, None]
    cfg = SEIBConfig(far_beta=far_beta)
    far = SEIB(reg, clf, 1.0, scale, cfg, beyond=True, far=True, box=([0.0], [1.0]))
    band = far.parts(grid)["band"]
    X = grid[band][:: max(1, int(band.sum()) // 6)]
    # by hand: rays of far_reach steps of min(l_R, l_S) = 0.05 along the outward normal (+-1 in 1-D),
    # kept while inside [0, 1] and 2 g_S length scales (0.1) or more from the failure at 0.85
    got = far.reach_ucb(X)
    assert np.isfinite(got).sum() >= 2  # open rays on the left; the right ones end at the failure
    for x, value in zip(X[:, 0], got):
        n = far.outward(np.array([[x]]))[0, 0]
        best = -np.inf
        for d in cfg.far_reach:
            t = x + d * 0.05 * n
            if not (0.0 <= t <= 1.0 and abs(t - 0.85) >= 0.1):
                break  # the ray ends at the box or at a known failure
            mu, var = reg.predict(np.array([[t]]))
            best = max(best, float(mu[0] + far_beta * np.sqrt(var[0])))
        assert value == pytest.approx(best, rel=1e-9, abs=1e-9 * scale)
    # the look beyond the band (one length scale out) keeps beta whatever far_beta is
    near = SEIB(reg, clf, 1.0, scale, cfg, beyond=True, box=([0.0], [1.0])).reach_ucb(X)
    plain = SEIB(reg, clf, 1.0, scale, beyond=True, box=([0.0], [1.0])).reach_ucb(X)
    np.testing.assert_array_equal(near, plain)


@pytest.mark.parametrize("p_band", [0.55, 0.6])
def test_values_are_the_parts_values_when_only_positive_latent_means_are_worked_out(p_band):
    """``SEIB(X)`` skips g_S's variance where its latent mean is <= 0 (p <= 1/2 < p_band there)."""
    reg, clf, scale = _valley_models(fail_left=True)
    grid = np.linspace(0, 1, 4001)[:, None]
    g = clf.predict_latent(grid)[0]
    assert np.any(g <= 0) and np.any(g > 0)
    positive = 0
    for kw in ({}, {"beyond": True}, {"beyond": True, "far": True}, {"gated": False}):
        acq = SEIB(reg, clf, 1.0, scale, SEIBConfig(p_band=p_band), box=([0.0], [1.0]), **kw)
        parts = acq.parts(grid)
        positive += int(np.any(parts["value"] > 0))
        np.testing.assert_allclose(acq(grid), parts["value"], rtol=1e-9, atol=1e-12)
    assert positive >= 2  # the comparison is not between zeros only


def test_the_maximiser_s_lattice_values_are_the_acquisition_s():
    """In 2-D the maximiser asks ``on_lattice`` for its 129^2 grid: the same values, the same point."""
    from corl.acquisition import maximize
    from corl.problem import Bounds

    rng = np.random.default_rng(0)
    X = rng.uniform(0, 1, size=(30, 2))
    s = np.linalg.norm(X - 0.5, axis=1) < 0.3
    clf = GPClassifier(SquaredExponential([0.1, 0.15], 10.0), prior_mean=-7.0).fit(X, s)
    reg = GPRegression(SquaredExponential(0.3, 1.0), 0.01).fit(X[s], -np.sum((X[s] - 0.7) ** 2, axis=1))
    acq = SEIB(reg, clf, float(np.max(-np.sum((X[s] - 0.7) ** 2, axis=1))), 0.05, box=([0, 0], [1, 1]))
    axes = [np.linspace(0, 1, 129)] * 2
    lattice = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    values = acq.parts(lattice)["value"]  # every term worked out everywhere
    assert np.any(values > 0)
    np.testing.assert_allclose(acq.on_lattice(lattice, axes), values, rtol=1e-9, atol=1e-12)

    class Plain:  # the acquisition as parts() computes it, without the shortcuts
        def __call__(self, Z):
            return acq.parts(Z)["value"]

    box = Bounds(np.zeros(2), np.ones(2))
    for extra in (X, None):
        fast = maximize(acq, box, rng=np.random.default_rng(1), extra=extra)
        plain = maximize(Plain(), box, rng=np.random.default_rng(1), extra=extra)
        np.testing.assert_allclose(fast[0], plain[0], atol=1e-12)
        assert fast[1] == pytest.approx(plain[1], rel=1e-9)


def test_behind_is_judged_along_the_ray_with_unequal_length_scales():
    """ARD g_S: a failure is behind only if it is behind the ray as the ray moves in g_S's length
    scales (direction n / l_S), not the normal scaled the other way (n * l_S)."""
    from corl.gp.kernels import SquaredExponential as SE

    ls = np.array([0.1, 1.0])

    class Classifier:  # latent mean 1 - x - y: outward normal (1, 1) / sqrt(2) everywhere
        kernel = SE(ls, 5.0)

        def __init__(self, failed):
            self.X_, self.y_ = np.vstack([[-0.05, 0.0], failed]), np.array([1.0] + [-1.0] * len(failed))

        def predict_latent(self, X):
            X = np.asarray(X)
            return 1.0 - X @ np.array([1.0, 1.0]), np.ones(len(X))

    class Regression:  # R rises outward: every open ray point promises a gain
        kernel, X_ = SE(ls, 1.0), np.zeros((0, 2))

        def predict(self, X):
            X = np.asarray(X)
            return X @ np.array([1.0, 1.0]), np.full(len(X), 1e-6)

    band = np.array([[0.0, 0.0]])
    near_ray = Classifier(np.array([[0.3, -1.2]]))  # within far_open of the ray points 2-4 length scales out
    behind = Classifier(np.array([[-0.15, -0.05]]))  # 1.5 g_S length scales away, but behind the ray
    far = dict(gated=True, beyond=True, far=True)
    closed = SEIB(Regression(), near_ray, 0.0, 1.0, SEIBConfig(_tuning=SEIBTuning(far_behind=0.25)), **far).reach_ucb(band)
    old_rule = SEIB(Regression(), near_ray, 0.0, 1.0, SEIBConfig(_tuning=SEIBTuning(far_behind=1.0)), **far).reach_ucb(band)
    opened = SEIB(Regression(), behind, 0.0, 1.0, SEIBConfig(_tuning=SEIBTuning(far_behind=0.25)), **far).reach_ucb(band)
    assert closed[0] == pytest.approx(old_rule[0])  # the failure near the ray still ends it
    assert opened[0] > closed[0] + 0.1  # the one behind does not ...
    blocked = SEIB(Regression(), behind, 0.0, 1.0, SEIBConfig(_tuning=SEIBTuning(far_behind=1.0)), **far).reach_ucb(band)
    assert blocked[0] == -np.inf  # ... which every failure did before


def test_in_six_dimensions_seeds_on_seib_s_level_land_in_its_band_where_sobol_points_do_not():
    from corl.acquisition.maximize import MaximizerConfig, _boundary_seeds, _initial_candidates
    from corl.gp.classification import expected_sigmoid
    from corl.gp.fitting import fit_classifier, fit_regression
    from corl.problem import Bounds

    rng = np.random.default_rng(0)
    box = Bounds(-np.ones(6), np.ones(6))
    ok = 0.03 * rng.standard_normal((8, 6))  # a run's first successes, close around the start at 0
    bad = 0.3 * rng.standard_normal((3, 6)) + 0.3  # and its failures further out
    X = np.vstack([ok, bad])
    s = np.r_[np.ones(8, bool), np.zeros(3, bool)]
    clf = fit_classifier(X, s, box, -7.0).model
    r = -np.sum((ok - 0.2) ** 2, axis=1)
    acq = SEIB(fit_regression(ok, r, box).model, clf, best_return=float(r.max()), scale=float(np.std(r)))
    g, g_var = clf.predict_latent(ok)
    np.testing.assert_allclose(acq.boundary_level(ok), expected_sigmoid(g, g_var) - 0.5 * (0.55 + 0.7), atol=1e-12)
    cfg = MaximizerConfig()
    U, _ = _initial_candidates(6, cfg, np.random.default_rng(1))
    in_band = lambda P: acq.parts(box.from_unit(P))["band"]  # noqa: E731
    assert not in_band(U).any()  # 4,096 Sobol points: none in the band of a safe set this small
    seeds = _boundary_seeds(acq.boundary_level, np.vstack([U[: cfg.level_samples], box.to_unit(X)]), box, cfg)
    assert len(seeds) >= 64 and in_band(seeds).mean() > 0.9  # the seeds: nearly all in it
