"""The methods of Fig. 1, built by name, for any task that provides ``w_bounds`` (methods over w).

Names are exactly those of the paper's table. ``CORL+PIBU(literal)`` is the ablation that reads
Eq. 17 word for word (see :mod:`corl.acquisition.pibu`).

Budgets (the paper does not state them), one number per kind of method, each counting black-box
trials: a method over ``w`` gets ``direct_budget`` trials in all, the demonstration included; CORL
gets ``corl.max_rl_trials`` black-box trials (step 2) over the whole run, all rounds together (the
start theta* is step 1's rollout, not one of them; see :class:`corl.learner.CORL`). The synthetic
presets, 99 and 49, are what the runs behind the paper tables used: the old accounting counted the
demonstration or the start theta* as one trial of a budget of 100 or 50.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from corl import checks
from corl.direct import DirectSearch
from corl.errors import InputError
from corl.learner import CORL
from corl.optimizers.registry import OPTIMIZERS
from corl.problem import Task, check_task
from corl.settings import MethodSettings  # re-exported: defined below the tasks

__all__ = ["MethodSettings", "METHODS", "PAPER_FIG1", "DEFAULT_METHOD", "USER_SETTINGS", "make_method", "settings_for"]

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


_UNCOUNTED = 2**62  # CORL counts its black-box trials itself; the optimizer inside never stops on a budget


#: A user's task (one without ``method_settings()``): GP hyperparameters learned from the data,
#: the same as ``MethodSettings()``.
USER_SETTINGS = MethodSettings()


def _factory(name: str, s: MethodSettings) -> Callable:
    """``(bounds, x0, rng, budget) -> BlackBoxOptimizer`` for the black-box part of a method (the registry's)."""
    if name not in OPTIMIZERS:
        raise InputError(f"unknown black-box method '{name}'; choose one of {', '.join(OPTIMIZERS)}")
    build, settings = OPTIMIZERS[name], s.optimizer_settings()
    return lambda b, x0, rng, n: build(b, x0, budget=n, rng=rng, settings=settings)


def settings_for(task: Task) -> MethodSettings:
    """The settings a method gets for ``task`` when none are given.

    The task's own (``task.method_settings()``: the paper's presets for the synthetic task and the
    door), or, for a task without it, :data:`USER_SETTINGS` (hyperparameters fitted from the data).
    Checked against the task's theta (:meth:`MethodSettings.check_task`) before any rollout.
    """
    preset = getattr(task, "method_settings", None)  # corl.problem.HasMethodSettings
    try:
        settings = preset() if callable(preset) else USER_SETTINGS
    except Exception as exc:  # the task's own code (or a setting it makes that is refused)
        raise InputError(f"task '{task.name}': method_settings() raised {type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:300]}; fix it (it returns a corl.settings.MethodSettings), "
                         "or remove it for settings fitted from the data") from exc
    if not isinstance(settings, MethodSettings):
        raise InputError(f"task '{task.name}': method_settings() returned {type(settings).__name__}; "
                         "it must return a corl.settings.MethodSettings")
    return settings.check_task(task)


def make_method(name: str, task: Task, *, seed: int = 0, settings: MethodSettings | None = None):
    """Build the learner called ``name`` (a Fig. 1 row) for ``task``; it speaks ask/tell/run.

    ``settings`` default to :func:`settings_for` the task. ``"CORL"`` is Alg. 1 with SEIB
    (:data:`DEFAULT_METHOD`).
    """
    if not isinstance(name, str) or not (name in METHODS or name.startswith("CORL+")):
        raise InputError(f"unknown method {name!r}; choose one of {', '.join(METHODS)}")
    check_task(task, "make_method's task")
    seed = checks.integer("seed", seed)
    if settings is None:
        settings = settings_for(task)
    elif not isinstance(settings, MethodSettings):
        raise InputError(f"make_method(settings=...) must be a corl.settings.MethodSettings, got {type(settings).__name__}")
    else:
        settings.check_task(task)
    if name == "CORL" or name.startswith("CORL+"):
        inner = _factory("SEIB" if name == "CORL" else name[len("CORL+"):], settings)
        return CORL(task, lambda b, x0, rng: inner(b, x0, rng, _UNCOUNTED), settings.corl, seed=seed)
    if name not in ("PIBU", "UCB", "CMA", "PoWER"):
        raise InputError(f"unknown method '{name}'; choose one of {', '.join(METHODS)}")
    if task.w_bounds is None:
        raise InputError(f"method '{name}' searches w directly and needs task.w_bounds; task '{task.name}' has none")
    rng = np.random.default_rng([seed, 12345])
    w0 = np.asarray(task.demonstration().w, dtype=float)
    inner = "PIBU(budget)" if name == "PIBU" else name
    optimizer = _factory(inner, settings)(task.w_bounds, w0, rng, settings.direct_budget)
    return DirectSearch(task, optimizer, failure_cost=-settings.failure_return)
