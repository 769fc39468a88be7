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

from corl.errors import InputError
from corl.gp.fitting import ClassifierPriors, RegressionPriors, fit_classifier, fit_regression

__all__ = ["RegressionConfig", "ClassifierConfig", "GPPreset", "ModelFitter", "PRESETS",
           "SYNTHETIC_REGRESSION", "SYNTHETIC_CLASSIFIER", "DOOR_REGRESSION", "DOOR_CLASSIFIER",
           "FITTED_REGRESSION", "FITTED_CLASSIFIER", "PAPER_SYNTHETIC", "PAPER_DOOR", "FITTED"]


@dataclass(frozen=True)
class RegressionConfig:
    """Return GP g_R: squared-exponential kernel (Eq. 16), Gaussian noise, constant prior mean.

    With ``fit_hyperparameters`` the fixed values are not used: every fit is a MAP fit under
    ``priors`` (unit box, standardised returns; the prior mean is the mean return).
    """

    lengthscale: float | tuple[float, ...] = 0.4  # one per dimension of theta for ARD (Eq. 16)
    signal_std: float = 10.0
    noise_std: float = 0.11
    prior_mean: float = 0.0
    fit_hyperparameters: bool = False
    priors: RegressionPriors = field(default_factory=RegressionPriors)

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.lengthscale) > 0) or self.signal_std <= 0 or self.noise_std < 0:
            raise InputError("GP regression needs lengthscale > 0, signal_std > 0 and noise_std >= 0")

    def build(self):
        """An unfitted GP with the fixed hyperparameters."""
        from corl.gp import GPRegression, SquaredExponential

        return GPRegression(SquaredExponential(self.lengthscale, self.signal_std), self.noise_std,
                            prior_mean=self.prior_mean)


@dataclass(frozen=True)
class ClassifierConfig:
    """Success GP g_S: logistic likelihood, Laplace approximation, negative constant prior mean.

    With ``fit_hyperparameters`` the length scales and signal std are MAP-fitted under ``priors``
    (unit box); the prior mean always stays ``prior_mean``.
    """

    lengthscale: float | tuple[float, ...] = 0.4  # one per dimension of theta for ARD (Eq. 16)
    signal_std: float = 10.0
    prior_mean: float = -7.0
    fit_hyperparameters: bool = False
    priors: ClassifierPriors = field(default_factory=ClassifierPriors)

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.lengthscale) > 0) or self.signal_std <= 0:
            raise InputError("GP classifier needs lengthscale > 0 and signal_std > 0")

    def build(self):
        """An unfitted classifier with the fixed hyperparameters."""
        from corl.gp import GPClassifier, SquaredExponential

        return GPClassifier(SquaredExponential(self.lengthscale, self.signal_std), prior_mean=self.prior_mean)


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
FITTED_REGRESSION = RegressionConfig(fit_hyperparameters=True)
FITTED_CLASSIFIER = ClassifierConfig(fit_hyperparameters=True)

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

    def regression(self, X, y):
        """g_R fitted on successful points ``X`` (d, m) with returns ``y`` (d,)."""
        cfg = self.regression_config
        if not cfg.fit_hyperparameters:
            return cfg.build().fit(X, y)
        res = fit_regression(X, y, self.bounds, cfg.priors, warm=self._warm["regression"])
        if not res.fallback:
            self._warm["regression"] = res.log_params
        self.fallback["regression"] = res.fallback
        return res.model

    def classifier(self, X, s):
        """g_S fitted on every point ``X`` (d, m) with outcomes ``s`` (d,)."""
        cfg = self.classifier_config
        if not cfg.fit_hyperparameters:
            return cfg.build().fit(X, s)
        res = fit_classifier(X, s, self.bounds, cfg.prior_mean, cfg.priors, warm=self._warm["classifier"],
                             previous=self._last_classifier)
        if not res.fallback:
            self._warm["classifier"] = res.log_params
        self.fallback["classifier"] = res.fallback
        self._last_classifier = res.model
        return res.model
