"""The settings a task gives corl, in one public place below the tasks.

A task's ``method_settings()`` (:class:`corl.problem.HasMethodSettings`) returns a
:class:`MethodSettings`: the GP hyperparameters in the task's units, Algorithm 1's trust region and
stopping thresholds, the budgets. Everything it is built from is importable from here::

    from corl.settings import MethodSettings, CORLConfig, RegressionConfig, ClassifierConfig

so a task never imports from ``corl.experiments`` (a floor above it). The presets of the paper's two
experiments (``SYNTHETIC_*``, ``DOOR_*``) are re-exported too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from corl.acquisition.safe_ei import SEIBConfig
from corl.errors import InputError
from corl.learner import CORLConfig
from corl.optimizers.gpconfig import (
    DOOR_CLASSIFIER,
    DOOR_REGRESSION,
    SYNTHETIC_CLASSIFIER,
    SYNTHETIC_REGRESSION,
    ClassifierConfig,
    RegressionConfig,
)
from corl.optimizers.registry import OptimizerSettings
from corl.trajectory.solver import SolverConfig

__all__ = ["MethodSettings", "CORLConfig", "SolverConfig", "RegressionConfig", "ClassifierConfig",
           "SYNTHETIC_REGRESSION", "SYNTHETIC_CLASSIFIER", "DOOR_REGRESSION", "DOOR_CLASSIFIER"]


@dataclass(frozen=True)
class MethodSettings:
    """Everything a method needs besides the task; the defaults are the synthetic benchmark's.

    Attributes
    ----------
    regression, classifier : GP hyperparameters of R and S over theta, in theta's units.
    corl : :class:`CORLConfig`, Algorithm 1 (trust region ``eps_max``, thresholds, rounds, solver);
        its ``max_rl_trials`` is CORL's one budget: black-box trials over the whole run.
    direct_budget : trials of a method that searches w directly, the demonstration included.
    failure_return : the return a safety-blind method is told for a failure.
    ucb_kappa, cma_sigma0 : UCB's exploration weight; CMA-ES's initial step in the unit box.
    seib : the acquisition settings of ``CORL``'s black-box step (:class:`SEIBConfig`).
    theta_scale : per-dimension unit of theta distances in the stopping rules (None: theta's own
        units). A task whose length scales are stretched per dimension (ARD) gives the same stretch
        here, so that "near a sampled point" means the same thing along every axis.
    """

    regression: RegressionConfig = SYNTHETIC_REGRESSION
    classifier: ClassifierConfig = SYNTHETIC_CLASSIFIER
    corl: CORLConfig = field(default_factory=lambda: CORLConfig(max_rl_trials=49))  # the budget of CORL
    direct_budget: int = 99  # trials of a method over w, the demonstration included
    failure_return: float = -15.0
    ucb_kappa: float = 2.0
    cma_sigma0: float = 0.3
    theta_scale: tuple[float, ...] | None = None
    seib: SEIBConfig = field(default_factory=SEIBConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.corl, CORLConfig):
            raise InputError(f"MethodSettings.corl must be a corl.settings.CORLConfig, got {type(self.corl).__name__}")
        if not isinstance(self.seib, SEIBConfig):
            raise InputError(f"MethodSettings.seib must be a corl.SEIBConfig, got {type(self.seib).__name__}")
        self.seib.check_classifier(self.classifier)  # far_lengthscale needs a fitted g_S: refused here, before a trial
        if isinstance(self.direct_budget, bool) or int(self.direct_budget) != self.direct_budget or self.direct_budget < 2:
            raise InputError(f"direct_budget (trials of a method over w, the demonstration included) must be an "
                             f"integer >= 2, got {self.direct_budget!r}")

    def optimizer_settings(self) -> OptimizerSettings:
        """The black-box methods' settings (:mod:`corl.optimizers.registry`) in the task's units."""
        return OptimizerSettings(regression=self.regression, classifier=self.classifier,
                                 failure_return=self.failure_return, ucb_kappa=self.ucb_kappa,
                                 cma_sigma0=self.cma_sigma0, stop_distance=1e-3, step_distance=self.corl.eps_theta,
                                 distance_scale=self.theta_scale, seib=self.seib)
