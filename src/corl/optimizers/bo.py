"""Bayesian optimization over theta with PIBU (Eq. 17) or UCB, one ask/tell interface.

After each ``tell``, the next decision (read through ``done``, ``stop_reason`` or ``ask``) refits
the GPs on all data told so far, builds the acquisition, maximises it and applies the stopping
rule, once (:mod:`corl.optimizers.base`). Stop reasons: ``NO_IMPROVEMENT`` when PIBU's acquisition
is zero everywhere, ``CONVERGED`` when the stopping rule fires, ``NO_SAFE_POINT`` while every trial
of PIBU failed, ``BUDGET``. ``PIBU`` uses the return GP on successes only and the success
classifier on all points; ``UCB`` ignores safety and models the score (return on success,
``failure_return`` on failure) with one GP.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field, replace

import numpy as np

from corl.acquisition import PIBU, MaximizerConfig, PIBUConfig, PIBUVariant, maximize, upper_confidence_bound
from corl.errors import InputError
from corl.optimizers.base import BlackBoxOptimizer, StopReason, as_rng, failure_score, model_returns
from corl.optimizers.gpconfig import SYNTHETIC_CLASSIFIER, SYNTHETIC_REGRESSION, ClassifierConfig, ModelFitter, RegressionConfig
from corl.problem import Bounds

__all__ = ["PIBUOptimizer", "UCBOptimizer", "StopRule", "BOConfig"]


class StopRule(str, enum.Enum):
    NEAR_SAMPLED = "near_sampled"  # next point within `stop_distance` of any sampled point
    SMALL_STEP = "small_step"  # ||theta_{d+1} - theta_d|| < stop_distance (Alg. 1, eps_theta)
    BUDGET = "budget"  # only max_evals


@dataclass(frozen=True)
class BOConfig:
    regression: RegressionConfig = SYNTHETIC_REGRESSION  # the paper's fixed values (Sec. VIII-A)
    classifier: ClassifierConfig = SYNTHETIC_CLASSIFIER
    maximizer: MaximizerConfig = field(default_factory=MaximizerConfig)
    stop_rule: StopRule = StopRule.NEAR_SAMPLED
    stop_distance: float = 1e-3
    distance_scale: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "stop_rule", StopRule(self.stop_rule))
        if self.stop_distance < 0:
            raise InputError(f"stop_distance must be >= 0, got {self.stop_distance}")
        if self.distance_scale is not None:
            scale = tuple(float(v) for v in np.atleast_1d(self.distance_scale))
            if not all(np.isfinite(v) and v > 0 for v in scale):
                raise InputError(f"distance_scale must hold positive finite numbers (one per theta dimension), "
                                 f"got {self.distance_scale}")
            object.__setattr__(self, "distance_scale", scale)


def _stop(rule: StopRule, x: np.ndarray, X: np.ndarray, distance: float,
          scale: tuple[float, ...] | None = None) -> bool:
    """The stopping rule; differences are divided by ``scale`` per dimension (the unit of ``distance``)."""
    if len(X) == 0 or rule is StopRule.BUDGET:
        return False
    unit = 1.0 if scale is None else np.asarray(scale, dtype=float)
    if np.ndim(unit) and unit.shape != x.shape:
        raise InputError(f"distance_scale has {unit.size} entries but theta has {x.size} dimensions")
    if rule is StopRule.NEAR_SAMPLED:
        return bool(np.min(np.linalg.norm((X - x) / unit, axis=1)) < distance)
    return bool(np.linalg.norm((X[-1] - x) / unit) < distance)


class _BayesOpt(BlackBoxOptimizer):
    """The BO loop shared by PIBU and UCB: ``_acquisition()`` on the data, maximised, then the stop rule.

    A subclass builds its acquisition in ``_acquisition`` (None: no data yet); ``_propose`` may
    also be overridden and return None (stop, ``CONVERGED``) or a :class:`StopReason`.
    """

    stop_when_zero = False

    def __init__(self, bounds: Bounds, config: BOConfig, *, max_evals: int, seed, name: str, start=None,
                 **kwargs) -> None:
        super().__init__(bounds, max_evals=max_evals, name=name, start=start, **kwargs)
        self.config = config
        self.rng = as_rng(seed)
        self.last_acquisition = None  # the acquisition of the latest ask, for plots
        self.models = ModelFitter(config.regression, config.classifier, bounds)  # fixed or fitted GPs

    def _propose(self) -> np.ndarray | StopReason:
        acq = self._acquisition()
        if acq is None:  # no data and no start: begin in the middle of the box
            return (self.bounds.lower + self.bounds.upper) / 2.0
        self.last_acquisition = acq
        x, value = maximize(acq, self.bounds, rng=self.rng, config=self.config.maximizer, extra=self.X_)
        if self.stop_when_zero and not value > 0.0:
            return StopReason.NO_IMPROVEMENT  # nothing to gain anywhere: no likely improvement, no uncertain boundary
        cfg = self.config
        if _stop(cfg.stop_rule, x, self.X_, cfg.stop_distance, cfg.distance_scale):
            return StopReason.CONVERGED
        return x

    def _acquisition(self):
        raise NotImplementedError


class PIBUOptimizer(_BayesOpt):
    """Safe Bayesian optimization with the PIBU acquisition (Eq. 17).

    Parameters
    ----------
    bounds : search box over theta, (m,) each.
    config : GP hyperparameters, maximiser and stopping rule.
    pibu : :class:`PIBUConfig` (variant and thresholds).
    max_evals, start : the budget (points told in all) and the first point (see :class:`BlackBoxOptimizer`).
    seed : int, Generator or None.
    """

    needs_success = True

    def __init__(self, bounds: Bounds, config: BOConfig = BOConfig(), pibu: PIBUConfig = PIBUConfig(), *,
                 max_evals: int = 100, seed=None, start=None, **kwargs) -> None:
        if pibu.variant is PIBUVariant.LITERAL and config.stop_rule is StopRule.NEAR_SAMPLED:
            config = replace(config, stop_rule=StopRule.SMALL_STEP)
        super().__init__(bounds, config, max_evals=max_evals, seed=seed, name="PIBU", start=start, **kwargs)
        self.stop_when_zero = True
        self.pibu = pibu

    def _acquisition(self):
        if len(self.X_) == 0:
            return None
        classifier = self.models.classifier(*self._safety_data())
        ok = self.success_ & np.isfinite(self.returns_)
        if np.any(ok):
            r = model_returns(self.returns_[ok], self.config.regression.fit_hyperparameters)  # (base.model_returns)
            regression = self.models.regression(self.X_[ok], r)
            best = float(np.max(r))
        else:
            regression, best = None, 0.0
        return PIBU(regression, classifier, best, self.pibu)


class UCBOptimizer(_BayesOpt):
    """Bayesian optimization with UCB on the score (ignores safety).

    Failures are modelled with the score ``failure_return`` (the paper's single objective gives
    failures a constant cost of 15), or with None one observed range below the worst success
    (:func:`~corl.optimizers.base.failure_score`: units-free, what fitted GPs get by default).
    """

    def __init__(self, bounds: Bounds, config: BOConfig = BOConfig(), *, kappa: float = 2.0,
                 failure_return: float | None = -15.0, max_evals: int = 100, seed=None, start=None) -> None:
        if kappa < 0:
            raise InputError(f"kappa must be >= 0, got {kappa}")
        super().__init__(bounds, config, max_evals=max_evals, seed=seed, name="UCB", start=start)
        self.kappa = kappa
        self.failure_return = failure_return

    def _acquisition(self):
        if len(self.X_) == 0:
            return None
        ok = self.success_ & np.isfinite(self.returns_)
        failed = failure_score(self.returns_[ok], self.failure_return)
        y = np.where(ok, self.returns_, failed)
        y = model_returns(y, self.config.regression.fit_hyperparameters)  # units-free when fitted (base.model_returns)
        return _UCB(self.models.regression(self.X_, y), self.kappa)


class _UCB:
    """UCB of a fitted GP at (s, m) points -> (s,): a class, not a closure, so the optimizer pickles."""

    def __init__(self, gp, kappa: float) -> None:
        self.gp, self.kappa = gp, kappa

    def __call__(self, X: np.ndarray) -> np.ndarray:
        mu, var = self.gp.predict(X)
        return upper_confidence_bound(mu, var, self.kappa)
