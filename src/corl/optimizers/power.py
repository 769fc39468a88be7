"""PoWER baseline (Sec. VIII-A): Policy learning by Weighting Exploration with the Returns.

Kober & Peters, "Policy search for motor primitives in robotics", Machine Learning 84, 2011,
episodic form with Gaussian exploration in parameter space and importance sampling over the best
rollouts seen so far (their Alg. 4 with state-independent exploration):

    x_k   = clip(mean + eps_k),  eps_k ~ N(0, Sigma)                  (exploration)
    mean <- mean + sum_k Q_k (x_k - mean) / sum_k Q_k                 (update, k over the n_best)

After each told rollout the mean is updated once. Since the weights are normalised, the update is
the Q-weighted average of the ``n_best`` best points, whatever the mean was when they were drawn.

Glossary
--------
mean  : the policy parameters being improved, (m,)
eps_k : exploration of rollout k, ``x_k - mean``, (m,)
Sigma : diagonal exploration covariance, ``diag((std * width)^2)``; ``std`` is a fraction of the box
Q_k   : non-negative weight of rollout k, from its score (see :func:`power_weights`)
score : ``R`` on success, ``failure_return`` on failure (the paper's single objective, negated)

Every told point is a rollout PoWER can use, also one that was not asked (a demonstration, a point
from another method): it enters the importance-sampling set like any other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl.errors import InputError
from corl.optimizers.base import BlackBoxOptimizer, StopReason, as_point, as_rng, score_of
from corl.problem import Bounds, Outcome

__all__ = ["PoWER", "PoWERConfig", "power_weights"]


@dataclass(frozen=True)
class PoWERConfig:
    """Settings of :class:`PoWER`.

    Attributes
    ----------
    n_best : size of the importance-sampling set, the best rollouts seen so far.
    std : initial exploration standard deviation, a fraction of the box width in every coordinate.
    decay : factor applied to ``std`` after each update, in (0, 1]; 1.0 keeps it constant.
    beta : sharpness of the weights ``Q`` (see :func:`power_weights`), > 0.
    tol_std : stop when ``std`` (a fraction of the box width) falls below it; 0.0 never stops.
    """

    n_best: int = 10
    std: float = 0.1
    decay: float = 1.0
    beta: float = 10.0
    tol_std: float = 0.0

    def __post_init__(self) -> None:
        if isinstance(self.n_best, bool) or int(self.n_best) != self.n_best or self.n_best < 1:
            raise InputError(f"n_best must be an integer >= 1, got {self.n_best!r}")
        object.__setattr__(self, "n_best", int(self.n_best))
        if not (np.isfinite(self.std) and self.std > 0.0):
            raise InputError(f"std is a fraction of the box width and must be > 0, got {self.std}")
        if not (0.0 < self.decay <= 1.0):
            raise InputError(f"decay must lie in (0, 1] (1.0 keeps the exploration constant), got {self.decay}")
        if not (np.isfinite(self.beta) and self.beta > 0.0):
            raise InputError(f"beta must be a positive number, got {self.beta}")
        if not (np.isfinite(self.tol_std) and self.tol_std >= 0.0):
            raise InputError(f"tol_std must be >= 0 (0.0 switches the rule off), got {self.tol_std}")


def power_weights(scores: np.ndarray, beta: float) -> np.ndarray:
    """Non-negative weights ``Q`` (k,) of the scores (k,): ``exp(-beta (max - s) / (max - min))``.

    ``scores`` are those of the importance-sampling set; max and min are taken over that set.

    PoWER needs ``Q >= 0``, but scores are returns that may be negative (every failure scores
    ``failure_return = -15``). Shifting by the maximum makes the best weight 1; dividing by the
    spread makes ``beta`` free of the return's units, so one ``beta`` serves the synthetic
    benchmark and the door alike (the same normalised exponential as PI2, which the paper relates
    to CMA). Unlike a rank transform it keeps how much better one rollout is than another: with
    ``beta = 10`` the worst rollout of the set weighs ``exp(-10) ~ 5e-5`` of the best, so a failure among the
    best set barely moves the mean. Equal scores give equal weights.
    """
    scores = np.asarray(scores, dtype=float)
    top = float(np.max(np.abs(scores))) if scores.size else 0.0
    if top > 1e300:  # the difference of two scores near 1.8e308 overflows; the weights are free of the unit
        scores = scores / top
    spread = float(np.max(scores) - np.min(scores)) if scores.size else 0.0
    if not spread > 0.0:
        return np.ones_like(scores)
    return np.exp(-beta * (np.max(scores) - scores) / spread)


class PoWER(BlackBoxOptimizer):
    """Episodic PoWER maximising ``score_of(outcome, failure_return)`` over a box.

    Parameters
    ----------
    bounds : search box, (m,) each.
    x0 : (m,) initial mean, inside ``bounds`` (e.g. the demonstration).
    config : importance-sampling set, exploration and weighting.
    failure_return : score of a failed trial (the paper's constant cost 15 -> -15.0).
    max_evals : trial budget; :attr:`done` turns True when it is spent.
    seed : int, Generator or None; the same seed gives the same sequence of points.
    start : (m,) or None: the first trial (see :class:`BlackBoxOptimizer`); it enters the
        importance-sampling set like any told point.

    Attributes
    ----------
    mean_ : (m,) current mean.
    std_ : current exploration standard deviation as a fraction of the box width.
    scores_ : (d,) score of every told point.
    """

    def __init__(self, bounds: Bounds, x0, config: PoWERConfig = PoWERConfig(), *,
                 failure_return: float = -15.0, max_evals: int = 100, seed=None, start=None) -> None:
        super().__init__(bounds, max_evals=max_evals, name="PoWER", start=start)
        if not np.isfinite(failure_return):
            raise InputError(f"failure_return must be finite, got {failure_return}")
        self.config = config
        self.failure_return = float(failure_return)
        self.rng = as_rng(seed)
        self.mean_ = as_point(x0, bounds, name=self.name, what="x0").copy()
        self.std_ = float(config.std)
        self.scores_ = np.empty(0)

    def _propose(self) -> np.ndarray | StopReason:
        if self.std_ < self.config.tol_std:
            return StopReason.CONVERGED  # the exploration fell below tol_std
        # exploration: x = mean + eps, eps ~ N(0, Sigma), Sigma = diag((std * width)^2)
        eps = self.std_ * self.bounds.width * self.rng.standard_normal(self.bounds.dim)
        return self.bounds.clip(self.mean_ + eps)

    def _observe(self, x: np.ndarray, outcome: Outcome) -> None:
        self.scores_ = np.append(self.scores_, score_of(outcome, self.failure_return))
        # importance sampling: the n_best highest scores so far (stable: earlier wins a tie)
        best = np.argsort(-self.scores_, kind="stable")[: self.config.n_best]
        Q = power_weights(self.scores_[best], self.config.beta)
        eps = self.X_[best] - self.mean_  # (k, m) exploration relative to the current mean
        # update: mean += sum_k Q_k eps_k / sum_k Q_k (sum_k Q_k >= 1, the best weighs 1)
        self.mean_ = self.bounds.clip(self.mean_ + Q @ eps / np.sum(Q))
        self.std_ *= self.config.decay
