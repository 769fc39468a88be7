"""The settings a task gives corl, in one public place below the tasks.

A task's ``method_settings()`` (:class:`corl.problem.HasMethodSettings`) returns a
:class:`MethodSettings`: the GP hyperparameters in the task's units, Algorithm 1's trust region and
stopping thresholds, the budgets. Everything it is built from is importable from here::

    from corl.settings import MethodSettings, CORLConfig, RegressionConfig, ClassifierConfig

so a task never imports from ``corl.experiments`` (a floor above it). ``MethodSettings()`` fits the
GPs from the data whatever other field a task sets; the paper's fixed values are presets a task
asks for by name (:data:`PAPER_SYNTHETIC`, ``SYNTHETIC_*``, ``DOOR_*``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from corl import checks
from corl.acquisition.safe_ei import SEIBConfig
from corl.errors import InputError
from corl.learner import CORLConfig
from corl.optimizers.gpconfig import (
    DOOR_CLASSIFIER,
    DOOR_REGRESSION,
    FITTED_CLASSIFIER,
    FITTED_REGRESSION,
    SYNTHETIC_CLASSIFIER,
    SYNTHETIC_REGRESSION,
    ClassifierConfig,
    RegressionConfig,
)
from corl.optimizers.registry import OptimizerSettings
from corl.trajectory.solver import SolverConfig

__all__ = ["MethodSettings", "CORLConfig", "SolverConfig", "RegressionConfig", "ClassifierConfig", "SEIBConfig",
           "SYNTHETIC_REGRESSION", "SYNTHETIC_CLASSIFIER", "DOOR_REGRESSION", "DOOR_CLASSIFIER",
           "FITTED_REGRESSION", "FITTED_CLASSIFIER", "PAPER_SYNTHETIC"]


_REMOVED = {"rl_budget": "CORL's budget is MethodSettings(corl=CORLConfig(max_rl_trials=N)); a method over w "
                        "has direct_budget=N"}


@checks.keywords(_REMOVED)
@dataclass(frozen=True)
class MethodSettings:
    """Everything a method needs besides the task. ``MethodSettings()`` is corl's default for a
    user's task: GP hyperparameters fitted from the data. The paper's fixed values are named
    presets that its tasks ask for explicitly: :data:`PAPER_SYNTHETIC` (the synthetic task) and
    ``DoorTask.method_settings()`` (the door, from :data:`DOOR_REGRESSION` and :data:`DOOR_CLASSIFIER`).

    Setting one field leaves the others at these defaults: ``MethodSettings(corl=CORLConfig(
    eps_max=0.1, max_rl_trials=40))`` still fits its GPs.

    Attributes
    ----------
    regression, classifier : GP hyperparameters of R and S over theta: fitted (the default,
        ``RegressionConfig()``), or fixed values in theta's and the return's units.
    corl : :class:`CORLConfig`, Algorithm 1 (trust region ``eps_max``, thresholds, rounds, solver);
        its ``max_rl_trials`` is CORL's one budget: black-box trials over the whole run.
    direct_budget : trials of a method that searches w directly, the demonstration included.
    failure_return : the return a safety-blind method is told for a failure.
    ucb_kappa, cma_sigma0 : UCB's exploration weight (>= 0); CMA-ES's initial step in the unit box (> 0).
    seib : the acquisition settings of ``CORL``'s black-box step (:class:`SEIBConfig`).
    confirm, label_noise, return_noise : for a robot whose readings err (:class:`corl.OptimizerSettings`):
        trials that repeat the black-box step's best before it stops, how often the success sensor errs
        (0: not declared) and a return reading's std in R's units (None: not declared).
    theta_scale : per-dimension unit of theta distances in the stopping rules (None: theta's own
        units; else one positive number per dimension of theta). A task whose length scales are
        stretched per dimension (ARD) gives the same stretch here, so that "near a sampled point"
        means the same thing along every axis.
    """

    regression: RegressionConfig = FITTED_REGRESSION
    classifier: ClassifierConfig = FITTED_CLASSIFIER
    corl: CORLConfig = field(default_factory=lambda: CORLConfig(max_rl_trials=49))  # the budget of CORL
    direct_budget: int = 99  # trials of a method over w, the demonstration included
    failure_return: float = -15.0
    ucb_kappa: float = 2.0
    cma_sigma0: float = 0.3
    theta_scale: tuple[float, ...] | None = None
    seib: SEIBConfig = field(default_factory=SEIBConfig)
    confirm: int = 0  # CORL: trials that repeat the black-box step's best before it stops (noisy returns)
    label_noise: float = 0.0  # CORL: how often the success sensor errs, if known (a stop one failure decides is rechecked)
    return_noise: float | None = None  # CORL: a return reading's std in R's units, if known (edges mapped beyond it)

    def __post_init__(self) -> None:
        for name, kind in (("regression", RegressionConfig), ("classifier", ClassifierConfig), ("corl", CORLConfig),
                           ("seib", SEIBConfig)):
            value = getattr(self, name)
            if not isinstance(value, kind):
                where = "corl" if kind is SEIBConfig else "corl.settings"
                raise InputError(f"MethodSettings.{name} must be a {where}.{kind.__name__}, got {type(value).__name__}")
        self.seib.check_classifier(self.classifier)  # far_lengthscale needs a fitted g_S: refused here, before a trial
        object.__setattr__(self, "direct_budget", checks.integer(
            "MethodSettings.direct_budget (trials of a method over w, the demonstration included)",
            self.direct_budget, low=2))
        object.__setattr__(self, "failure_return", checks.number("MethodSettings.failure_return", self.failure_return))
        object.__setattr__(self, "confirm", checks.integer("MethodSettings.confirm", self.confirm))
        object.__setattr__(self, "label_noise", checks.number("MethodSettings.label_noise (how often the success "
                                                              "sensor errs)", self.label_noise, low=0.0, high=0.5,
                                                              high_open=True))
        object.__setattr__(self, "ucb_kappa", checks.number("MethodSettings.ucb_kappa", self.ucb_kappa, low=0.0))
        object.__setattr__(self, "cma_sigma0", checks.number("MethodSettings.cma_sigma0", self.cma_sigma0, low=0.0,
                                                             low_open=True))
        if self.theta_scale is not None:
            scale = checks.lengths("MethodSettings.theta_scale", self.theta_scale)
            object.__setattr__(self, "theta_scale", scale if isinstance(scale, tuple) else (scale,))

    def check_task(self, task) -> "MethodSettings":
        """Refuse settings whose lengths do not fit ``task``'s theta (before any rollout); returns self."""
        m = task.theta_bounds.dim
        self.regression.check_dimension(m, "MethodSettings.regression")
        self.classifier.check_dimension(m, "MethodSettings.classifier")
        if self.theta_scale is not None and len(self.theta_scale) != m:
            raise InputError(f"MethodSettings.theta_scale has {len(self.theta_scale)} values but theta has {m} "
                             "dimensions; give one per dimension")
        return self

    def optimizer_settings(self) -> OptimizerSettings:
        """The black-box methods' settings (:mod:`corl.optimizers.registry`) in the task's units."""
        return OptimizerSettings(regression=self.regression, classifier=self.classifier,
                                 failure_return=self.failure_return, ucb_kappa=self.ucb_kappa,
                                 cma_sigma0=self.cma_sigma0, stop_distance=1e-3, step_distance=self.corl.eps_theta,
                                 distance_scale=self.theta_scale, seib=self.seib, confirm=self.confirm,
                                 label_noise=self.label_noise, return_noise=self.return_noise)


#: The paper's synthetic benchmark (Sec. VIII-A, Fig. 1): its fixed GP values (in its own units)
#: and the budgets behind the published table. The synthetic task asks for it explicitly
#: (``SyntheticTask.method_settings``); the door's preset is ``DoorTask.method_settings``.
PAPER_SYNTHETIC = MethodSettings(regression=SYNTHETIC_REGRESSION, classifier=SYNTHETIC_CLASSIFIER)
