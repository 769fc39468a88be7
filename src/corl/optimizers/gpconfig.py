"""Hyperparameters of the two GPs used by the Bayesian optimizers, with the paper's presets."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl.errors import InputError

__all__ = ["RegressionConfig", "ClassifierConfig", "SYNTHETIC_REGRESSION", "SYNTHETIC_CLASSIFIER",
           "DOOR_REGRESSION", "DOOR_CLASSIFIER"]


@dataclass(frozen=True)
class RegressionConfig:
    """Return GP g_R: squared-exponential kernel (Eq. 16), Gaussian noise, constant prior mean."""

    lengthscale: float | tuple[float, ...] = 0.4  # one per dimension of theta for ARD (Eq. 16)
    signal_std: float = 10.0
    noise_std: float = 0.11
    prior_mean: float = 0.0
    fit_hyperparameters: bool = False

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.lengthscale) > 0) or self.signal_std <= 0 or self.noise_std < 0:
            raise InputError("GP regression needs lengthscale > 0, signal_std > 0 and noise_std >= 0")

    def build(self):
        from corl.gp import GPRegression, SquaredExponential

        return GPRegression(SquaredExponential(self.lengthscale, self.signal_std), self.noise_std,
                            prior_mean=self.prior_mean)


@dataclass(frozen=True)
class ClassifierConfig:
    """Success GP g_S: logistic likelihood, Laplace approximation, negative constant prior mean."""

    lengthscale: float | tuple[float, ...] = 0.4  # one per dimension of theta for ARD (Eq. 16)
    signal_std: float = 10.0
    prior_mean: float = -7.0
    fit_hyperparameters: bool = False

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.lengthscale) > 0) or self.signal_std <= 0:
            raise InputError("GP classifier needs lengthscale > 0 and signal_std > 0")

    def build(self):
        from corl.gp import GPClassifier, SquaredExponential

        return GPClassifier(SquaredExponential(self.lengthscale, self.signal_std), prior_mean=self.prior_mean)


# Sec. VIII-A (synthetic benchmark)
SYNTHETIC_REGRESSION = RegressionConfig(lengthscale=0.4, signal_std=10.0, noise_std=0.11)
SYNTHETIC_CLASSIFIER = ClassifierConfig(lengthscale=0.4, signal_std=10.0, prior_mean=-7.0)
# Sec. VIII-B (PR2 door)
DOOR_REGRESSION = RegressionConfig(lengthscale=0.0417, signal_std=0.1682, noise_std=0.0120)
DOOR_CLASSIFIER = ClassifierConfig(lengthscale=0.02, signal_std=10.0, prior_mean=-7.0)
