"""Hyperparameters of the two GPs used by the Bayesian optimizers: fixed (the paper) or fitted.

Two presets:

* ``paper`` -- the fixed values of Sec. VIII (``SYNTHETIC_*`` for the synthetic benchmark,
  ``DOOR_*`` for the door). ``corl bench synthetic`` and ``corl bench door`` use them.
* ``fitted`` -- MAP hyperparameters learned from the data at every fit, in unit-box units with
  weak priors relative to the box (:mod:`corl.gp.fitting`). The default for a user's task: no
  number to guess.

:class:`ModelFitter` is what an optimizer holds: it fits g_R and g_S from its data and carries
the previous fit's hyperparameters as the next warm start.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from corl import checks
from corl.errors import InputError
from corl.gp.fitting import ClassifierPriors, RegressionPriors, fit_classifier, fit_regression

__all__ = ["RegressionConfig", "ClassifierConfig", "GPPreset", "ModelFitter", "PRESETS",
           "SYNTHETIC_REGRESSION", "SYNTHETIC_CLASSIFIER", "DOOR_REGRESSION", "DOOR_CLASSIFIER",
           "FITTED_REGRESSION", "FITTED_CLASSIFIER", "PAPER_SYNTHETIC", "PAPER_DOOR", "FITTED"]


def _resolve(owner, values: dict, fit) -> bool:
    """Whether ``owner``'s hyperparameters are fitted: yes when no value is given, no when all are.

    A config means what it says: ``RegressionConfig()`` fits every hyperparameter from the data,
    ``RegressionConfig(lengthscale=.., signal_std=.., noise_std=..)`` fixes all of them; a partial
    set is refused rather than completed with the paper's synthetic values (in the return's units,
    which are not the user's)."""
    name = type(owner).__name__
    given = [k for k, v in values.items() if v is not None]
    if fit is not None:
        fit = checks.flag(f"{name}.fit_hyperparameters", fit)
    if fit is None:
        fit = not given
    if fit and given:
        raise InputError(f"{name}: fitted hyperparameters ignore {', '.join(given)}; drop "
                         f"{'it' if len(given) == 1 else 'them'}, or set fit_hyperparameters=False to fix them")
    if not fit and len(given) < len(values):
        missing = [k for k in values if values[k] is None]
        raise InputError(f"{name}: fixed hyperparameters need {', '.join(values)} together; {', '.join(missing)} "
                         f"missing. Give {'it' if len(missing) == 1 else 'them'} (the paper's presets are "
                         f"corl.settings.SYNTHETIC_* and DOOR_*), or none to fit all from the data")
    return fit


@checks.keywords()
@dataclass(frozen=True)
class RegressionConfig:
    """Return GP g_R: squared-exponential kernel (Eq. 16), Gaussian noise, constant prior mean.

    ``RegressionConfig()`` fits the hyperparameters from the data (every fit a MAP fit under
    ``priors``: unit box, standardised returns; the prior mean is the mean return). Giving
    ``lengthscale``, ``signal_std`` and ``noise_std`` (all three, in theta's and the return's units)
    fixes them instead; the paper's values are :data:`SYNTHETIC_REGRESSION` and :data:`DOOR_REGRESSION`.
    """

    lengthscale: float | tuple[float, ...] | None = None  # one per dimension of theta for ARD (Eq. 16)
    signal_std: float | None = None
    noise_std: float | None = None
    prior_mean: float = 0.0
    fit_hyperparameters: bool | None = None  # None: fitted exactly when no value above is given
    priors: RegressionPriors = field(default_factory=RegressionPriors)

    def __post_init__(self) -> None:
        name = "RegressionConfig"
        fit = _resolve(self, {"lengthscale": self.lengthscale, "signal_std": self.signal_std,
                              "noise_std": self.noise_std}, self.fit_hyperparameters)
        object.__setattr__(self, "fit_hyperparameters", fit)
        if not fit:
            object.__setattr__(self, "lengthscale", checks.lengths(f"{name}.lengthscale", self.lengthscale))
            object.__setattr__(self, "signal_std", checks.number(f"{name}.signal_std", self.signal_std, low=0.0,
                                                                 low_open=True))
            object.__setattr__(self, "noise_std", checks.number(f"{name}.noise_std", self.noise_std, low=0.0))
        object.__setattr__(self, "prior_mean", checks.number(f"{name}.prior_mean", self.prior_mean))
        if not isinstance(self.priors, RegressionPriors):
            raise InputError(f"{name}.priors must be a corl.gp.fitting.RegressionPriors, got {type(self.priors).__name__}")

    def build(self):
        """An unfitted GP with the fixed hyperparameters."""
        from corl.gp import GPRegression, SquaredExponential

        if self.fit_hyperparameters:
            raise InputError("RegressionConfig.build() needs fixed hyperparameters; fitted ones come from ModelFitter")
        return GPRegression(SquaredExponential(self.lengthscale, self.signal_std), self.noise_std,
                            prior_mean=self.prior_mean)

    def check_dimension(self, m: int, owner: str = "RegressionConfig") -> None:
        """Refuse a length-scale tuple whose length is not theta's dimension ``m``."""
        _check_dimension(owner, self.lengthscale, m)


@checks.keywords()
@dataclass(frozen=True)
class ClassifierConfig:
    """Success GP g_S: logistic likelihood, Laplace approximation, negative constant prior mean.

    ``ClassifierConfig()`` MAP-fits the length scales and signal std under ``priors`` (unit box);
    giving ``lengthscale`` and ``signal_std`` (both) fixes them instead. The prior mean is always
    ``prior_mean``. The paper's values are :data:`SYNTHETIC_CLASSIFIER` and :data:`DOOR_CLASSIFIER`.
    """

    lengthscale: float | tuple[float, ...] | None = None  # one per dimension of theta for ARD (Eq. 16)
    signal_std: float | None = None
    prior_mean: float = -7.0
    fit_hyperparameters: bool | None = None  # None: fitted exactly when no value above is given
    priors: ClassifierPriors = field(default_factory=ClassifierPriors)

    def __post_init__(self) -> None:
        name = "ClassifierConfig"
        fit = _resolve(self, {"lengthscale": self.lengthscale, "signal_std": self.signal_std},
                       self.fit_hyperparameters)
        object.__setattr__(self, "fit_hyperparameters", fit)
        if not fit:
            object.__setattr__(self, "lengthscale", checks.lengths(f"{name}.lengthscale", self.lengthscale))
            object.__setattr__(self, "signal_std", checks.number(f"{name}.signal_std", self.signal_std, low=0.0,
                                                                 low_open=True))
        object.__setattr__(self, "prior_mean", checks.number(f"{name}.prior_mean", self.prior_mean))
        if not isinstance(self.priors, ClassifierPriors):
            raise InputError(f"{name}.priors must be a corl.gp.fitting.ClassifierPriors, got {type(self.priors).__name__}")

    def build(self):
        """An unfitted classifier with the fixed hyperparameters."""
        from corl.gp import GPClassifier, SquaredExponential

        if self.fit_hyperparameters:
            raise InputError("ClassifierConfig.build() needs fixed hyperparameters; fitted ones come from ModelFitter")
        return GPClassifier(SquaredExponential(self.lengthscale, self.signal_std), prior_mean=self.prior_mean)

    def check_dimension(self, m: int, owner: str = "ClassifierConfig") -> None:
        """Refuse a length-scale tuple whose length is not theta's dimension ``m``."""
        _check_dimension(owner, self.lengthscale, m)


def _check_dimension(owner: str, lengthscale, m: int) -> None:
    if isinstance(lengthscale, tuple) and len(lengthscale) != m:
        raise InputError(f"{owner}.lengthscale has {len(lengthscale)} values but theta has {m} dimensions; "
                         "give one per dimension, or one number for all")


@dataclass(frozen=True)
class GPPreset:
    """A named pair of GP configurations."""

    name: str
    regression: RegressionConfig
    classifier: ClassifierConfig


# Sec. VIII-A (synthetic benchmark)
SYNTHETIC_REGRESSION = RegressionConfig(lengthscale=0.4, signal_std=10.0, noise_std=0.11)
SYNTHETIC_CLASSIFIER = ClassifierConfig(lengthscale=0.4, signal_std=10.0, prior_mean=-7.0)
# Sec. VIII-B (PR2 door)
DOOR_REGRESSION = RegressionConfig(lengthscale=0.0417, signal_std=0.1682, noise_std=0.0120)
DOOR_CLASSIFIER = ClassifierConfig(lengthscale=0.02, signal_std=10.0, prior_mean=-7.0)
# Learned from the data (user tasks)
FITTED_REGRESSION = RegressionConfig()  # no value given: fitted
FITTED_CLASSIFIER = ClassifierConfig()

PAPER_SYNTHETIC = GPPreset("paper", SYNTHETIC_REGRESSION, SYNTHETIC_CLASSIFIER)
PAPER_DOOR = GPPreset("paper", DOOR_REGRESSION, DOOR_CLASSIFIER)
FITTED = GPPreset("fitted", FITTED_REGRESSION, FITTED_CLASSIFIER)
PRESETS = {"paper": PAPER_SYNTHETIC, "paper-door": PAPER_DOOR, "fitted": FITTED}


class ModelFitter:
    """Fits g_R and g_S for one optimizer over ``bounds``, warm-starting each fit from the last.

    Parameters
    ----------
    regression, classifier : the configurations; fixed ones are simply built and fitted.
    bounds : :class:`corl.problem.Bounds` of theta (defines the unit box of fitted models).

    Attributes
    ----------
    fallback : ``{"regression": reason, "classifier": reason}`` of the latest fits ("" = fitted).
    """

    def __init__(self, regression: RegressionConfig, classifier: ClassifierConfig, bounds) -> None:
        self.regression_config, self.classifier_config, self.bounds = regression, classifier, bounds
        self._warm: dict[str, np.ndarray | None] = {"regression": None, "classifier": None}
        self._last_classifier = None
        self.fallback: dict[str, str] = {}

    def regression(self, X, y, *, keep: bool = True):
        """g_R fitted on successful points ``X`` (d, m) with returns ``y`` (d,).

        ``keep=False`` leaves the warm start as it was: a fit for a report (the learner's best)
        must not change the next decision's fit.
        """
        cfg = self.regression_config
        if not cfg.fit_hyperparameters:
            return cfg.build().fit(X, y)
        res = fit_regression(X, y, self.bounds, cfg.priors, warm=self._warm["regression"])
        if keep:
            if not res.fallback:
                self._warm["regression"] = res.log_params
            self.fallback["regression"] = res.fallback
        return res.model

    def classifier(self, X, s, *, keep: bool = True):
        """g_S fitted on every point ``X`` (d, m) with outcomes ``s`` (d,); ``keep`` as in :meth:`regression`."""
        cfg = self.classifier_config
        if not cfg.fit_hyperparameters:
            return cfg.build().fit(X, s)
        res = fit_classifier(X, s, self.bounds, cfg.prior_mean, cfg.priors, warm=self._warm["classifier"],
                             previous=self._last_classifier)
        if keep:
            if not res.fallback:
                self._warm["classifier"] = res.log_params
            self.fallback["classifier"] = res.fallback
            self._last_classifier = res.model
        return res.model
