"""Probability of improvement (Eq. 14-15) and upper confidence bound.

Glossary
--------
mu, var : predictive mean and latent variance of the return GP g_R at candidates, (s,)
best    : R(theta^+), the highest return observed on a success (Eq. 15)
kappa   : UCB exploration weight, ``mu + kappa * sqrt(var)``
"""

from __future__ import annotations

import numpy as np

from corl.numerics import floor_variance, ndtr

__all__ = ["probability_of_improvement", "upper_confidence_bound"]


def probability_of_improvement(mu: np.ndarray, var: np.ndarray, best: float) -> np.ndarray:
    """Eq. 14: ``PI = Phi((mu - R(theta^+)) / sqrt(V))``; ``mu``, ``var``: (s,) -> (s,) in [0, 1]."""
    return ndtr((np.asarray(mu) - best) / np.sqrt(floor_variance(np.asarray(var))))


def upper_confidence_bound(mu: np.ndarray, var: np.ndarray, kappa: float) -> np.ndarray:
    """UCB (Brochu et al. 2010): ``mu + kappa * sqrt(V)``; ``mu``, ``var``: (s,) -> (s,)."""
    return np.asarray(mu) + kappa * np.sqrt(floor_variance(np.asarray(var)))
