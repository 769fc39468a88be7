"""The CORL default optimizer (SafeBOOptimizer): safe search, bad input, registration."""

from dataclasses import fields

import numpy as np
import pytest

from blackbox_loop import C2, UNIT2, quadratic
from corl.errors import InputError, StateError
from corl.optimizers.base import StopReason
from corl.optimizers.gpconfig import ClassifierConfig
from corl.optimizers.safe import SafeBOOptimizer, return_scale
from corl.problem import Outcome


def _loop(opt, rollout, n):
    for _ in range(n):
        if opt.done:
            break
        try:
            x = opt.ask()
        except StateError:  # converged
            break
        opt.tell(x, rollout(x))


def test_finds_an_inner_optimum_with_failures_only_near_the_boundary():
    rollout = quadratic(C2, fail_above=0.8)  # optimum (0.3, 0.7) inside, unsafe above x2 = 0.8
    opt = SafeBOOptimizer(UNIT2, max_evals=30, seed=0)
    start = np.array([0.6, 0.2])
    opt.tell(start, rollout(start))
    _loop(opt, rollout, 30)
    x_best, r_best = opt.best
    assert r_best > -0.01  # within 0.1 of C2
    failed = opt.X_[~opt.success_]
    assert np.all(failed[:, 1] < 0.8 + 0.1)  # no failure far past the boundary
    assert len(failed) <= 5


def test_all_failure_history_gets_a_clear_error_and_stays_usable():
    rollout = quadratic(C2, fail_above=0.8)
    opt = SafeBOOptimizer(UNIT2, max_evals=20, seed=0)
    opt.tell(np.array([0.5, 0.9]), Outcome(False))
    opt.tell(np.array([0.4, 0.95]), Outcome(False))
    assert opt.done and opt.stop_reason is StopReason.NO_SAFE_POINT  # known before ask: a safe method never guesses
    with pytest.raises(StateError, match="succeed"):
        opt.ask()
    start = np.array([0.5, 0.5])
    opt.tell(start, rollout(start))
    assert not opt.done and opt.stop_reason is None  # a success: the method decides again
    x = opt.ask()
    assert UNIT2.contains(x) and np.all(np.isfinite(x))


def test_duplicate_points_keep_the_optimizer_usable():
    rollout = quadratic(C2, fail_above=0.8)
    opt = SafeBOOptimizer(UNIT2, max_evals=20, seed=0)
    x0 = np.array([0.5, 0.5])
    for _ in range(4):
        opt.tell(x0, rollout(x0))
    opt.tell(np.array([0.5, 0.9]), Outcome(False))
    opt.tell(np.array([0.5, 0.9]), Outcome(False))
    x = opt.ask()
    assert UNIT2.contains(x) and np.all(np.isfinite(x))
    assert np.min(np.linalg.norm(opt.X_ - x, axis=1)) > 1e-3  # a new point, not a repeat


def test_nan_return_is_refused_and_loses_nothing():
    opt = SafeBOOptimizer(UNIT2, max_evals=20, seed=0)
    opt.tell(np.array([0.5, 0.5]), Outcome(True, 1.0))
    with pytest.raises(InputError):
        opt.tell(np.array([0.4, 0.5]), Outcome(True, float("nan")))
    assert opt.n_evals == 1
    assert np.all(np.isfinite(opt.ask()))


def test_return_scale():
    assert return_scale(np.array([1.0, 3.0])) == pytest.approx(1.0)
    assert return_scale(np.array([-4.0])) == 4.0
    assert return_scale(np.array([0.0, 0.0])) == 1.0


def test_return_scale_of_returns_whose_squares_overflow():
    assert return_scale(np.array([1e300, -1e300])) == pytest.approx(1e300, rel=1e-12)
    assert return_scale(np.array([1.7e308, 1.7e308])) == 1.7e308  # no spread: the magnitude
    assert return_scale(np.array([3e200, 1e200])) == pytest.approx(1e200, rel=1e-12)


def test_corl_is_registered_and_uses_the_safe_optimizer():
    from corl.methods import DEFAULT_METHOD, METHODS, make_method
    from corl.tasks.synthetic import SyntheticTask

    assert DEFAULT_METHOD == "CORL" and "CORL" in METHODS
    task = SyntheticTask(np.array([0.0, 0.5]))
    learner = make_method("CORL", task, seed=0)
    opt = learner.optimizer_factory(task.theta_bounds, np.zeros(1), np.random.default_rng(0))
    assert isinstance(opt, SafeBOOptimizer)


def _local_peak_rollout(x):
    """The paper's 1-D synthetic problem: safe on (-1.5, 2.5), R = -x^2 / 2 + cos 3x (global max at 0)."""
    x = float(x[0])
    if not -1.5 < x < 2.5:
        return Outcome(False, None)
    return Outcome(True, -0.5 * x * x + np.cos(3.0 * x))


def _one_d_runs(box, start, rollout, seibs):
    """One 40-trial run from ``start`` per named SEIBConfig on the 1-D box ``(low, high)``."""
    from corl.problem import Bounds

    bounds = Bounds(np.array([box[0]]), np.array([box[1]]))
    runs = {}
    for name, seib in seibs:
        opt = SafeBOOptimizer(bounds, seib=seib, max_evals=40, seed=0)
        opt.tell(np.array([start]), rollout(np.array([start])))
        _loop(opt, rollout, 39)
        runs[name] = opt
    return runs


def test_looks_beyond_the_band_instead_of_stopping_at_a_local_peak():
    from corl.acquisition.safe_ei import SEIBConfig, SEIBTuning

    band_only = SEIBConfig(far=False, _tuning=SEIBTuning(beyond_rel=np.inf))
    runs = _one_d_runs((-np.pi, np.pi), 1.8, _local_peak_rollout, [("band only", band_only), ("beyond", SEIBConfig())])
    old, new = runs["band only"], runs["beyond"]
    assert abs(old.best[0][0] - 1.88) < 0.1 and old.n_evals < 10  # the band-point gate stops at the local peak
    assert abs(new.best[0][0]) < 0.05 and new.best[1] > 0.99  # looking beyond crosses the valley to 0
    assert np.sum(~new.success_) <= 2 and new.n_evals < 40  # ... with few failures, and still stops
    assert new.stop_reason in (StopReason.NO_IMPROVEMENT, StopReason.CONVERGED)


def _valley_rollout(theta):  # valley-like: safe on (1, 9), a local peak at 2.8 by the start, the optimum at 7.5
    x = float(np.asarray(theta).reshape(-1)[0])
    if not 1.0 < x < 9.0:
        return Outcome(False, None)
    return Outcome(True, 0.7 * np.exp(-((x - 2.8) ** 2) / 0.5) + np.exp(-((x - 7.5) ** 2) / 0.8))


def test_looks_far_across_a_valley_wider_than_a_length_scale():
    from corl.acquisition.safe_ei import SEIBConfig

    runs = _one_d_runs((0.0, 10.0), 2.5, _valley_rollout, [("beyond", SEIBConfig(far=False)), ("far", SEIBConfig())])
    near, far = runs["beyond"], runs["far"]
    assert near.best[1] < 0.71 and near.stop_reason is not StopReason.BUDGET  # stops at the local peak
    assert abs(far.best[0][0] - 7.5) < 0.1 and far.best[1] > 0.99  # looking far crosses to the optimum
    assert np.sum(~far.success_) <= 2 and far.n_evals < 40  # with few failures, and still stops


def _wide_valley_rollout(theta):  # safe on (1, 9), a local peak at 2.8 by the start, the optimum at 8.5
    x = float(np.asarray(theta).reshape(-1)[0])
    if not 1.0 < x < 9.0:
        return Outcome(False, None)
    return Outcome(True, 0.7 * np.exp(-((x - 2.8) ** 2) / 0.5) + np.exp(-((x - 8.5) ** 2) / 0.8))


def test_seib_has_five_user_settings_and_a_removed_one_says_where_it_went():
    from corl.acquisition import safe_ei
    from corl.acquisition.safe_ei import SEIBConfig

    assert [f.name for f in fields(SEIBConfig) if not f.name.startswith("_")] == [
        "p_band", "band_rel", "far", "far_beta", "far_lengthscale"]
    with pytest.raises(InputError, match="far_ladder.*far_lengthscale"):
        SEIBConfig(far_ladder=(3.0,))
    with pytest.raises(InputError, match="named constant corl.acquisition.safe_ei.TRUST_PER_DIM"):
        SEIBConfig(trust_per_dim=0)
    with pytest.raises(InputError, match="far=False"):
        SEIBConfig(far_reach=())
    cfg = SEIBConfig()  # the fixed values are the module's named constants
    assert (cfg.p_inner, cfg.xi_rel, cfg.stop_value, cfg.far_reach) == (
        safe_ei.P_INNER, safe_ei.XI_REL, safe_ei.STOP_VALUE, safe_ei.FAR_REACH)
    with pytest.raises(InputError, match="far_behind"):
        safe_ei.SEIBTuning(far_behind=None)
    with pytest.raises(InputError, match="far must be True or False"):
        SEIBConfig(far="no")


def test_a_user_sets_corl_s_acquisition_through_the_public_settings():
    from dataclasses import replace

    import corl

    box = (np.array([0.0]), np.array([10.0]))
    fitted = corl.OptimizerSettings.for_box(corl.Bounds(*box), fitted=True)
    assert fitted.regression.fit_hyperparameters and fitted.seib == corl.SEIBConfig()
    runs = {}
    for name, settings in [("default", None), ("no far look", replace(fitted, seib=corl.SEIBConfig(far=False)))]:
        result = corl.optimize(_valley_rollout, box, start=[2.5], method="CORL", budget=40, seed=0, settings=settings)
        runs[name] = result
    assert runs["default"].return_ > 0.99  # crosses the valley (as the test above, through corl.optimize)
    assert runs["no far look"].return_ < 0.71 and runs["no far look"].trials < runs["default"].trials


def test_method_settings_carry_seib_to_corl_s_black_box_step():
    from dataclasses import replace

    from corl.acquisition.safe_ei import SEIBConfig
    from corl.methods import USER_SETTINGS

    mine = SEIBConfig(far=False, p_band=0.6)
    assert USER_SETTINGS.optimizer_settings().seib == SEIBConfig()
    assert replace(USER_SETTINGS, seib=mine).optimizer_settings().seib is mine


def test_a_wrong_seib_setting_is_refused_where_it_is_made():
    from dataclasses import replace

    import corl
    from corl.methods import USER_SETTINGS

    fitted = corl.OptimizerSettings.for_box(corl.Bounds(np.array([0.0]), np.array([1.0])), fitted=True)
    with pytest.raises(InputError, match="OptimizerSettings.seib must be a corl.SEIBConfig, got str"):
        replace(fitted, seib="far")
    with pytest.raises(InputError, match="MethodSettings.seib must be a corl.SEIBConfig, got dict"):
        replace(USER_SETTINGS, seib={"far_reach": ()})


def test_a_decision_reuses_predictions_at_the_same_candidates():
    """Asking SEIB again in one decision (beyond, far) reuses g_S's posterior on the same lattice."""
    from corl.optimizers.safe import _Reuse

    class Counting:
        calls = 0
        kernel = "k"

        def predict_latent(self, X):
            Counting.calls += 1
            return X[:, 0] * 2.0, X[:, 0] ** 2

    model = _Reuse(Counting())
    X = np.random.default_rng(0).random((50, 2))
    first = model.predict_latent(X)
    again = model.predict_latent(X.copy())  # equal values, another array
    other = model.predict_latent(X + 1e-12)  # any difference: computed
    assert Counting.calls == 2 and again is first and not np.array_equal(other[0], first[0])
    assert model.kernel == "k"  # everything else is the model's
    opt = SafeBOOptimizer(UNIT2, max_evals=30, seed=0)
    rollout = quadratic(C2, fail_above=0.8)
    opt.tell(np.array([0.6, 0.2]), rollout(np.array([0.6, 0.2])))
    _loop(opt, rollout, 5)
    assert isinstance(opt._models[1], _Reuse) and isinstance(opt._models[2], _Reuse)
    clf = opt._models[2]
    grid = np.random.default_rng(1).random((2000, 2))
    assert clf.predict_latent_positive(grid) is clf.predict_latent_positive(grid.copy())
    for _ in range(20):  # other calls in between (a look makes about ten) do not evict it
        clf.predict_latent(np.random.default_rng(2).random((3, 2)))
    assert clf.predict_latent_positive(grid) is clf.predict_latent_positive(grid)
    reg = opt._models[1]
    noisy = reg.predict(grid[:5], include_noise=True)[1]  # keyword calls go to the model itself
    assert np.all(noisy > reg.predict(grid[:5])[1])


def test_an_optimizer_can_be_copied_and_pickled_after_a_decision():
    import copy
    import pickle

    opt = SafeBOOptimizer(UNIT2, max_evals=30, seed=0)
    rollout = quadratic(C2, fail_above=0.8)
    opt.tell(np.array([0.6, 0.2]), rollout(np.array([0.6, 0.2])))
    x = opt.ask()
    for twin in (copy.deepcopy(opt), pickle.loads(pickle.dumps(opt))):
        np.testing.assert_array_equal(twin.ask(), x)
        twin.tell(x, rollout(x))
        assert twin.n_evals == 2 and opt.n_evals == 1


def test_the_readme_s_cautious_and_bold_settings_reach_the_optimizer():
    from dataclasses import replace

    import corl
    from corl.gp.fitting import ClassifierPriors, HyperPrior

    box = corl.Bounds([0.0, 0.0], [2.0, 4.0])
    base = corl.OptimizerSettings.for_box(box, fitted=True)
    cautious = replace(base, seib=corl.SEIBConfig(band_rel=0.05))
    bold = replace(base, classifier=replace(base.classifier,
                   priors=ClassifierPriors(lengthscale=HyperPrior(0.15, 0.75, 0.03, 3.0))))
    far = replace(base, seib=corl.SEIBConfig(far_lengthscale=0.15))
    rollout = quadratic(C2, fail_above=0.8)
    for settings, check in ((cautious, lambda o: o.seib.band_rel == 0.05),
                            (bold, lambda o: o.models.classifier_config.priors.lengthscale.median == 0.15),
                            (far, lambda o: o.seib.far_lengthscale == 0.15)):
        opt = corl.make_optimizer("CORL", box, [0.6, 0.2], settings=settings, budget=6, seed=0)
        assert check(opt)
        opt.tell(np.array([0.6, 0.2]), rollout(np.array([0.6, 0.2])))
        opt.tell(np.array([0.7, 0.3]), rollout(np.array([0.7, 0.3])))
        opt.tell(np.array([0.5, 0.9]), rollout(np.array([0.5, 0.9])))  # a failure: g_S is fitted
        x = opt.ask()
        assert box.contains(x)
    # the fitted g_S's unit-box length scale starts from the bold prior's median
    opt = corl.make_optimizer("CORL", box, [0.6, 0.2], settings=bold, budget=6, seed=0)
    opt.tell(np.array([0.6, 0.2]), rollout(np.array([0.6, 0.2])))
    opt.done
    np.testing.assert_allclose(np.asarray(opt._models[2].kernel.lengthscales) / box.width, 0.15)


def test_far_lengthscale_steps_further_only_in_the_far_look_and_crosses_the_valley():
    from corl.acquisition.safe_ei import SEIBConfig
    from corl.problem import Bounds

    class Recorded(SafeBOOptimizer):
        first_far = None

        def _acquisition(self, **how):
            if how.get("far") and self.first_far is None:
                self.first_far = len(self.X_)
            return super()._acquisition(**how)

    bounds = Bounds(np.array([0.0]), np.array([10.0]))
    runs = {}
    for name, seib in (("default", SEIBConfig()), ("far", SEIBConfig(far_lengthscale=0.15))):
        opt = Recorded(bounds, seib=seib, max_evals=40, seed=0)
        opt.tell(np.array([2.5]), _wide_valley_rollout(np.array([2.5])))
        _loop(opt, _wide_valley_rollout, 39)
        runs[name] = opt
    default, far = runs["default"], runs["far"]
    assert default.best[1] < 0.71  # the default stops at the local peak by the start
    n = far.first_far
    assert n is not None and n == default.first_far
    np.testing.assert_array_equal(far.X_[:n], default.X_[:n])  # the same run up to the first far look ...
    assert abs(far.best[0][0] - 8.5) < 0.1 and far.best[1] > 0.99  # ... then across the valley
    assert np.all(far.success_) and far.n_evals < 40 and far.stop_reason is StopReason.NO_IMPROVEMENT
    # the far look's g_S: with every trial a success, the fit falls back to the far prior median
    acq = far._acquisition(beyond=True, far=True)
    np.testing.assert_allclose(np.asarray(acq.classifier.kernel.lengthscales) / bounds.width, 0.15)
    np.testing.assert_allclose(np.asarray(far._acquisition().classifier.kernel.lengthscales) / bounds.width, 0.1)


def test_far_lengthscale_is_checked_where_it_is_made():
    from corl.acquisition.safe_ei import SEIBConfig
    from corl.optimizers.bo import BOConfig

    for bad in (0.0, -0.1, float("nan"), float("inf"), True, "0.2"):
        with pytest.raises(InputError, match="far_lengthscale"):
            SEIBConfig(far_lengthscale=bad)
    hash(SEIBConfig(far_lengthscale=0.2))
    with pytest.raises(InputError, match="prior bounds"):
        SafeBOOptimizer(UNIT2, seib=SEIBConfig(far_lengthscale=5.0))
    fixed = BOConfig(classifier=ClassifierConfig(lengthscale=0.1, signal_std=10.0))
    with pytest.raises(InputError, match="fixed"):
        SafeBOOptimizer(UNIT2, fixed, seib=SEIBConfig(far_lengthscale=0.15))
    assert SEIBConfig(far_lengthscale=np.float32(0.2)).far_lengthscale == pytest.approx(0.2)
    SEIBConfig(far_lengthscale=np.int64(1))  # a NumPy integer is a number too


def test_far_lengthscale_with_fixed_gp_values_is_refused_where_the_settings_are_made():
    """Before a trial: a task's method_settings() or OptimizerSettings, not the first far look."""
    from dataclasses import replace

    import corl
    from corl.acquisition.safe_ei import SEIBConfig
    from corl.settings import PAPER_SYNTHETIC, MethodSettings

    far = SEIBConfig(far_lengthscale=0.15)
    with pytest.raises(InputError, match="fixed"):
        replace(PAPER_SYNTHETIC, seib=far)  # the paper's fixed values
    MethodSettings(seib=far)  # the default fits g_S: fine
    with pytest.raises(InputError, match="fixed"):
        replace(corl.OptimizerSettings.for_box(UNIT2), seib=far)
    with pytest.raises(InputError, match="prior bounds"):
        replace(corl.OptimizerSettings.for_box(UNIT2, fitted=True), seib=SEIBConfig(far_lengthscale=4.0))
    replace(corl.methods.USER_SETTINGS, seib=far)  # fitted: fine
    opt = corl.make_optimizer("CORL", UNIT2, [0.5, 0.5], budget=5)
    opt.seib = far  # replaced after construction: still refused, at the far look
    opt.models.classifier_config = ClassifierConfig(lengthscale=0.1, signal_std=10.0)
    with pytest.raises(InputError, match="fixed"):
        opt._far_look_classifier()
