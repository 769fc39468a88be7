"""The methods of Fig. 1, built by name, for any task that provides ``w_bounds`` (methods over w).

Names are exactly those of the paper's table. ``CORL+PIBU(literal)`` is the ablation that reads
Eq. 17 word for word (see :mod:`corl.acquisition.pibu`).

Budgets (the paper does not state them): methods over ``w`` get ``direct_budget`` trials
(demonstration included); the black-box step of CORL gets at most ``rl_budget`` trials per round.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from corl.acquisition import PIBUConfig, PIBUVariant
from corl.direct import DirectSearch
from corl.errors import InputError
from corl.learner import CORL
from corl.optimizers.bo import PIBUOptimizer, StopRule, UCBOptimizer
from corl.optimizers.cmaes import CMAES, CMAESConfig
from corl.optimizers.power import PoWER, PoWERConfig
from corl.optimizers.sal import SALConfig, SALOptimizer
from corl.problem import Task
from corl.settings import MethodSettings  # re-exported: defined below the tasks

__all__ = ["MethodSettings", "METHODS", "PAPER_FIG1", "make_method"]

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
METHODS = tuple(PAPER_FIG1) + ("CORL+PIBU(literal)",)


def _factory(name: str, s: MethodSettings) -> Callable:
    """``(bounds, x0, rng) -> BlackBoxOptimizer`` for the black-box part of a method."""
    eps_theta = s.corl.eps_theta
    if name == "PIBU":
        return lambda b, x0, rng, n: PIBUOptimizer(b, s.bo(), max_evals=n, seed=rng)
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
    hyperparameters from Sec. VIII-B) or, for tasks without them, the synthetic benchmark's.
    """
    if settings is None:
        preset = getattr(task, "method_settings", None)  # corl.problem.HasMethodSettings
        settings = preset() if callable(preset) else MethodSettings()
        if not isinstance(settings, MethodSettings):
            raise InputError(f"task '{task.name}': method_settings() returned {type(settings).__name__}; "
                             "it must return a corl.settings.MethodSettings")
    if name.startswith("CORL+"):
        inner = _factory(name[len("CORL+"):], settings)
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
