"""The methods of Fig. 1, built by name, for any task that provides ``w_bounds`` (methods over w).

Names are exactly those of the paper's table. ``CORL+PIBU(literal)`` is the ablation that reads
Eq. 17 word for word (see :mod:`corl.acquisition.pibu`).

Budgets (the paper does not state them): methods over ``w`` get ``direct_budget`` trials
(demonstration included); the black-box step of CORL gets at most ``rl_budget`` trials per round.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from corl.acquisition import PIBUConfig, PIBUVariant
from corl.direct import DirectSearch
from corl.errors import InputError
from corl.learner import CORL, CORLConfig
from corl.optimizers.bo import BOConfig, PIBUOptimizer, StopRule, UCBOptimizer
from corl.optimizers.cmaes import CMAES, CMAESConfig
from corl.optimizers.gpconfig import (
    FITTED_CLASSIFIER, FITTED_REGRESSION, SYNTHETIC_CLASSIFIER, SYNTHETIC_REGRESSION, ClassifierConfig, RegressionConfig,
)
from corl.optimizers.power import PoWER, PoWERConfig
from corl.optimizers.safe import SAFE_BO_CONFIG, SafeBOOptimizer
from corl.optimizers.sal import SALConfig, SALOptimizer
from corl.problem import Task

__all__ = ["MethodSettings", "METHODS", "PAPER_FIG1", "DEFAULT_METHOD", "USER_SETTINGS", "make_method"]

PAPER_FIG1 = {  # found/100, failures mean, std, max distance mean, std
    "PIBU": (100, 8.49, 1.35, 0.71, 0.44),
    "PoWER": (67, 8.36, 5.91, 1.34, 0.43),
    "UCB": (97, 14.53, 1.07, 1.48, 0.11),
    "CMA": (77, 7.74, 4.41, 1.28, 0.35),
    "CORL+PIBU": (100, 2.04, 0.19, 0.10, 0.04),
    "CORL+UCB": (92, 4.38, 0.98, 1.25, 0.69),
    "CORL+CMA": (85, 2.98, 2.58, 1.26, 1.15),
    "CORL+SAL": (99, 1.74, 0.56, 0.06, 0.11),
}
METHODS = tuple(PAPER_FIG1) + ("CORL+PIBU(literal)", "CORL")
#: ``CORL``: the default for a user's task -- Alg. 1 with safe BO by SEIB on GPs fitted from the
#: data (corl.optimizers.safe); not a row of Fig. 1.
DEFAULT_METHOD = "CORL"


@dataclass(frozen=True)
class MethodSettings:
    """Everything a method needs besides the task; the defaults are the synthetic benchmark's."""

    regression: RegressionConfig = SYNTHETIC_REGRESSION
    classifier: ClassifierConfig = SYNTHETIC_CLASSIFIER
    corl: CORLConfig = field(default_factory=CORLConfig)
    direct_budget: int = 100
    rl_budget: int = 50
    failure_return: float = -15.0
    ucb_kappa: float = 2.0
    cma_sigma0: float = 0.3
    # Per-dimension unit of theta distances in the stopping rules (None: theta's own units). A
    # task whose length scales are stretched per dimension (ARD) gives the same stretch here, so
    # that "near a sampled point" means the same thing along every axis.
    theta_scale: tuple[float, ...] | None = None

    def bo(self, stop_rule: StopRule = StopRule.NEAR_SAMPLED, stop_distance: float = 1e-3) -> BOConfig:
        return BOConfig(self.regression, self.classifier, stop_rule=stop_rule, stop_distance=stop_distance,
                        distance_scale=self.theta_scale)


#: A user's task (one without ``method_settings()``): GP hyperparameters learned from the data.
USER_SETTINGS = MethodSettings(regression=FITTED_REGRESSION, classifier=FITTED_CLASSIFIER)


def _factory(name: str, s: MethodSettings) -> Callable:
    """``(bounds, x0, rng) -> BlackBoxOptimizer`` for the black-box part of a method."""
    eps_theta = s.corl.eps_theta
    if name == "PIBU":
        return lambda b, x0, rng, n: PIBUOptimizer(b, s.bo(), max_evals=n, seed=rng)
    if name == "SEIB":  # the CORL default; its GPs follow the settings (fitted for user tasks)
        cfg = replace(SAFE_BO_CONFIG, regression=s.regression, classifier=s.classifier)
        return lambda b, x0, rng, n: SafeBOOptimizer(b, cfg, max_evals=n, seed=rng)
    if name == "PIBU(budget)":  # over w: the 1e-3 stopping rule fires before the optimum is pinned down
        return lambda b, x0, rng, n: PIBUOptimizer(b, s.bo(StopRule.BUDGET), max_evals=n, seed=rng)
    if name == "PIBU(literal)":
        return lambda b, x0, rng, n: PIBUOptimizer(b, s.bo(StopRule.SMALL_STEP, eps_theta),
                                                   PIBUConfig(variant=PIBUVariant.LITERAL), max_evals=n, seed=rng)
    if name == "UCB":
        return lambda b, x0, rng, n: UCBOptimizer(b, s.bo(StopRule.SMALL_STEP, eps_theta), kappa=s.ucb_kappa,
                                                  failure_return=s.failure_return, max_evals=n, seed=rng)
    if name == "SAL":
        cfg = SALConfig(regression=s.regression)
        return lambda b, x0, rng, n: SALOptimizer(b, cfg, max_evals=n, seed=rng)
    if name == "CMA":
        return lambda b, x0, rng, n: CMAES(b, x0, CMAESConfig(sigma0=s.cma_sigma0), failure_return=s.failure_return,
                                           max_evals=n, seed=rng)
    if name == "PoWER":
        return lambda b, x0, rng, n: PoWER(b, x0, PoWERConfig(), failure_return=s.failure_return, max_evals=n, seed=rng)
    raise InputError(f"unknown black-box method '{name}'; choose one of PIBU, UCB, SAL, CMA, PoWER")


def make_method(name: str, task: Task, *, seed: int = 0, settings: MethodSettings | None = None):
    """Build the learner called ``name`` (a Fig. 1 row) for ``task``; it speaks ask/tell/run.

    ``settings`` default to the task's own (``task.method_settings()``, e.g. the door's
    hyperparameters from Sec. VIII-B), the paper's synthetic values for the synthetic task, or,
    for a user's task, :data:`USER_SETTINGS` (hyperparameters fitted from the data).
    ``"CORL"`` is Alg. 1 with SEIB (:data:`DEFAULT_METHOD`).
    """
    if settings is None:
        preset = getattr(task, "method_settings", None)
        if callable(preset):
            settings = preset()
        else:
            settings = MethodSettings() if getattr(task, "name", None) == "synthetic" else USER_SETTINGS
    if name == "CORL" or name.startswith("CORL+"):
        inner = _factory("SEIB" if name == "CORL" else name[len("CORL+"):], settings)
        budget = settings.corl.max_rl_trials if settings.rl_budget is None else settings.rl_budget
        corl_cfg = replace(settings.corl, max_rl_trials=budget)
        return CORL(task, lambda b, x0, rng: inner(b, x0, rng, budget), corl_cfg, seed=seed)
    if name not in ("PIBU", "UCB", "CMA", "PoWER"):
        raise InputError(f"unknown method '{name}'; choose one of {', '.join(METHODS)}")
    if task.w_bounds is None:
        raise InputError(f"method '{name}' searches w directly and needs task.w_bounds; task '{task.name}' has none")
    rng = np.random.default_rng([seed, 12345])
    w0 = np.asarray(task.demonstration().w, dtype=float)
    inner = "PIBU(budget)" if name == "PIBU" else name
    optimizer = _factory(inner, settings)(task.w_bounds, w0, rng, settings.direct_budget - 1)
    return DirectSearch(task, optimizer, failure_cost=-settings.failure_return)
