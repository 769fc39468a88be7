"""Settings mean what they say (issue 21, part 3): defaults fit the GPs whatever else a task sets;
every setting is checked where it is made, and against the task before the first rollout."""

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from corl.acquisition.safe_ei import SEIBTuning
from corl.errors import InputError
from corl.learner import CORLConfig
from corl.methods import USER_SETTINGS, make_method, settings_for
from corl.problem import Bounds
from corl.settings import (DOOR_REGRESSION, PAPER_SYNTHETIC, SYNTHETIC_REGRESSION, ClassifierConfig,
                           MethodSettings, RegressionConfig, SEIBConfig, SolverConfig)

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from examples.planar_button import PlanarButtonTask  # noqa: E402

BUDGET = CORLConfig(eps_max=0.2, eps_w=1e-4, max_rl_trials=12)


class OnlyBudget(PlanarButtonTask):
    """A user's task whose method_settings() sets only the trust region and the budget."""

    def method_settings(self):
        return MethodSettings(corl=BUDGET)


class NoSettings(PlanarButtonTask):
    method_settings = None  # corl's defaults for a user's task


def _decisions(learner):
    learner.run(max_trials=200)
    return [(p.step, tuple(np.round(p.theta, 12)), o.success) for p, o in learner.history]


def test_setting_only_the_budget_keeps_fitted_gps_and_the_same_decisions():
    settings = settings_for(OnlyBudget())
    assert settings.regression.fit_hyperparameters and settings.classifier.fit_hyperparameters
    mine = _decisions(make_method("CORL", OnlyBudget(), seed=3))
    default = _decisions(make_method("CORL", NoSettings(), seed=3, settings=replace(USER_SETTINGS, corl=BUDGET)))
    assert sum(step == "reinforcement" for step, _, _ in mine) >= 3  # the black-box step made decisions
    assert mine == default


def test_defaults_are_fitted_and_the_paper_values_are_named_presets():
    assert MethodSettings() == USER_SETTINGS
    assert RegressionConfig().fit_hyperparameters and ClassifierConfig().fit_hyperparameters
    assert not PAPER_SYNTHETIC.regression.fit_hyperparameters and PAPER_SYNTHETIC.regression == SYNTHETIC_REGRESSION
    from corl.tasks.synthetic import SyntheticTask

    assert settings_for(SyntheticTask()) is PAPER_SYNTHETIC  # the paper's task asks for them by name
    assert replace(DOOR_REGRESSION, lengthscale=(0.1, 0.2)).lengthscale == (0.1, 0.2)


@pytest.mark.parametrize("make, match", [
    (lambda: RegressionConfig(lengthscale=0.2), "signal_std, noise_std missing"),
    (lambda: ClassifierConfig(signal_std=3.0), "lengthscale missing"),
    (lambda: RegressionConfig(lengthscale=0.2, fit_hyperparameters=True), "fitted hyperparameters ignore lengthscale"),
    (lambda: RegressionConfig(fit_hyperparameters=False), "missing"),
    (lambda: RegressionConfig(lengthscale="wide", signal_std=1.0, noise_std=0.1), "RegressionConfig.lengthscale"),
    (lambda: RegressionConfig(lengthscale=(0.1, -1.0), signal_std=1.0, noise_std=0.1), r"lengthscale\[1\]"),
    (lambda: RegressionConfig(lengthscale=0.1, signal_std=1.0, noise_std=math.nan), "noise_std"),
    (lambda: ClassifierConfig(prior_mean=math.inf), "prior_mean"),
    (lambda: CORLConfig(max_rl_trials="10"), "max_rl_trials"),
    (lambda: CORLConfig(max_rl_trials=math.nan), "max_rl_trials"),
    (lambda: CORLConfig(max_rl_trials=2.5), "max_rl_trials"),
    (lambda: CORLConfig(eps_max=math.nan), "eps_max"),
    (lambda: CORLConfig(rollout_every_step="no"), "rollout_every_step"),
    (lambda: CORLConfig(rl_budget=40), "CORLConfig\\(max_rl_trials=N\\)"),
    (lambda: CORLConfig(eps_maks=0.1), "no setting 'eps_maks'"),
    (lambda: MethodSettings(rl_budget=40), "max_rl_trials=N"),
    (lambda: MethodSettings(failure_return="bad"), "failure_return"),
    (lambda: MethodSettings(ucb_kappa=math.nan), "ucb_kappa"),
    (lambda: MethodSettings(cma_sigma0=-0.1), "cma_sigma0"),
    (lambda: MethodSettings(theta_scale=(1.0, -2.0)), "theta_scale"),
    (lambda: MethodSettings(direct_budget=2.5), "direct_budget"),
    (lambda: MethodSettings(corl={"eps_max": 0.1}), "MethodSettings.corl"),
    (lambda: SEIBTuning(stop_value=math.inf), "stop_value"),
    (lambda: SEIBConfig(stop_valu=1.0), "no setting 'stop_valu'"),
    (lambda: SolverConfig(tol_steps=1.0), "no setting 'tol_steps'"),
    (lambda: Bounds(np.array([]), np.array([])), "empty"),
])
def test_a_bad_setting_is_refused_where_it_is_made_in_one_line(make, match):
    with pytest.raises(InputError, match=match) as err:
        make()
    assert "\n" not in str(err.value)


class Counting(PlanarButtonTask):
    """Counts rollouts: a setting that does not fit the task must be refused before the first."""

    rollouts = 0

    def rollout(self, w):
        Counting.rollouts += 1
        return super().rollout(w)


@pytest.mark.parametrize("settings, match", [
    (MethodSettings(regression=RegressionConfig(lengthscale=(0.01, 0.02), signal_std=1.0, noise_std=0.1)),
     "regression.lengthscale has 2 values but theta has 1"),
    (MethodSettings(classifier=ClassifierConfig(lengthscale=(0.01, 0.02), signal_std=1.0)), "classifier.lengthscale"),
    (MethodSettings(theta_scale=(1.0, 2.0)), "theta_scale has 2 values"),
])
def test_settings_that_do_not_fit_theta_are_refused_before_any_rollout(settings, match):
    Counting.rollouts = 0
    with pytest.raises(InputError, match=match):
        make_method("CORL", Counting(), settings=settings)

    class Own(Counting):
        def method_settings(self):
            return settings

    with pytest.raises(InputError, match=match):
        make_method("CORL+PIBU", Own())
    assert Counting.rollouts == 0
