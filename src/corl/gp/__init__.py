"""Gaussian process models of Sec. VII-A: regression for the return R and classification for S.

:class:`GPRegression` is the return model g_R (Eq. 11-12), :class:`GPClassifier` the success model
g_S (Eq. 13, Laplace approximation with a constant negative prior mean), both with the squared
exponential kernel of Eq. 16. Models know nothing of acquisitions. :mod:`corl.gp.fitting` learns
both models' hyperparameters from the data (MAP in unit-box units, with fallbacks). The paper's
hyperparameters and the fitted presets live in one place, :mod:`corl.optimizers.gpconfig`.
"""

from corl.gp.classification import GPClassifier, expected_sigmoid
from corl.gp.fitting import fit_classifier, fit_regression
from corl.gp.kernels import SquaredExponential
from corl.gp.regression import GPRegression

__all__ = [
    "SquaredExponential",
    "GPRegression",
    "GPClassifier",
    "expected_sigmoid",
    "fit_regression",
    "fit_classifier",
]
