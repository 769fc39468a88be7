"""SAL-style safe exploration (Schreiter et al., ECML-PKDD 2015), adapted to optimization.

SAL assumes that in *critical* but feasible regions the learner observes a safety measure, the
distance to the feasibility boundary, besides the binary outcome (Sec. VIII-A notes that no other
method sees it). A task reports it as ``outcome.info["boundary_distance"]`` when the trial is
within the critical distance of the boundary; tasks that cannot measure it simply omit it.

Safety model: a GP regression ``g`` over the clipped, signed safety signal

    z = min(boundary_distance, d_crit)   on success (``d_crit`` when no distance was reported)
    z = -d_crit                          on failure

with prior mean ``-d_crit`` (unexplored space counts as unsafe, like PIBU's negative prior mean).
A candidate is safe when ``P(g > 0) = Phi(mu_g / sigma_g) >= 1 - alpha``. Among safe candidates the
next point maximises UCB of the return GP (successes only); SAL's own criterion, the differential
entropy of the return GP, is the ``kappa -> inf`` limit. This regression on a clipped signal is
our simplification of SAL's mixed class/regression likelihood; it keeps SAL's defining feature,
the extra distance observation near the boundary.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from corl.acquisition import MaximizerConfig, maximize, upper_confidence_bound
from corl.errors import InputError
from corl.numerics import floor_variance, ndtr
from corl.optimizers.base import _MISSING, BlackBoxOptimizer, StopReason, _told, as_outcome, as_rng, model_returns
from corl.optimizers.bo import StopRule, _stop
from corl.optimizers.gpconfig import SYNTHETIC_REGRESSION, ClassifierConfig, ModelFitter, RegressionConfig
from corl.problem import Bounds

__all__ = ["SALConfig", "SALOptimizer"]


@dataclass(frozen=True)
class SALConfig:
    regression: RegressionConfig = SYNTHETIC_REGRESSION  # the paper's fixed values (Sec. VIII-A)
    critical_distance: float = 0.5
    safety_lengthscale: float = 0.4
    safety_noise: float = 0.02
    alpha: float = 0.05
    kappa: float = 2.0
    maximizer: MaximizerConfig = field(default_factory=MaximizerConfig)
    stop_rule: StopRule = StopRule.NEAR_SAMPLED
    stop_distance: float = 1e-3

    def __post_init__(self) -> None:
        object.__setattr__(self, "stop_rule", StopRule(self.stop_rule))
        if self.critical_distance <= 0 or self.safety_lengthscale <= 0 or self.safety_noise < 0:
            raise InputError("SAL needs critical_distance > 0, safety_lengthscale > 0, safety_noise >= 0")
        if not 0.0 < self.alpha < 1.0:
            raise InputError(f"alpha must lie in (0, 1), got {self.alpha}")


class SALOptimizer(BlackBoxOptimizer):
    """Safe exploration with an observed distance to the boundary (see module docstring)."""

    needs_success = True  # the return GP needs a success; NO_SAFE_POINT before that

    def __init__(self, bounds: Bounds, config: SALConfig = SALConfig(), *, max_evals: int = 100, seed=None,
                 start=None) -> None:
        super().__init__(bounds, max_evals=max_evals, name="SAL", start=start)
        self.config = config
        self.rng = as_rng(seed)
        self.safety_ = np.empty(0)
        # g_R's MAP fits (with warm starts) when its hyperparameters are fitted; g_S is SAL's own safety GP
        self._fitter = ModelFitter(config.regression, ClassifierConfig(), bounds)

    def tell(self, x, outcome=_MISSING) -> None:
        """As :meth:`BlackBoxOptimizer.tell`; ``info["boundary_distance"]``, when given on a success,
        must be a finite number (else :class:`~corl.errors.InputError`, nothing recorded)."""
        outcome = as_outcome(_told(x, outcome))
        dist = outcome.info.get("boundary_distance") if outcome.success and outcome.info else None
        if dist is not None:
            try:
                ok = not isinstance(dist, (bool, np.bool_)) and np.isfinite(float(dist))
            except (TypeError, ValueError, OverflowError):
                ok = False
            if not ok:
                raise InputError(f"info['boundary_distance'] must be a finite number (the distance to the boundary "
                                 f"of the safe set) or left out, got {dist!r:.40}")
        super().tell(x, outcome)

    def _observe(self, x, outcome) -> None:
        d_crit = self.config.critical_distance
        if outcome.success:
            dist = outcome.info.get("boundary_distance") if outcome.info else None
            z = d_crit if dist is None else min(float(dist), d_crit)
        else:
            z = -d_crit
        self.safety_ = np.append(self.safety_, z)

    def safety_model(self):
        """The safety GP ``g`` fitted on all data; ``P(g > 0) = Phi(mu / sigma)``."""
        from corl.gp import GPRegression, SquaredExponential

        cfg = self.config
        kernel = SquaredExponential(cfg.safety_lengthscale, cfg.critical_distance)
        return GPRegression(kernel, cfg.safety_noise, prior_mean=-cfg.critical_distance).fit(self.X_, self.safety_)

    def safe_probability(self, X: np.ndarray, model=None) -> np.ndarray:
        """``P(g(x) > 0)`` at candidates ``X`` (s, m) -> (s,)."""
        mu, var = (model or self.safety_model()).predict(X)
        return ndtr(mu / np.sqrt(floor_variance(var)))

    def _propose(self) -> np.ndarray | StopReason:
        if len(self.X_) == 0:
            return (self.bounds.lower + self.bounds.upper) / 2.0
        cfg = self.config
        ok = self.success_ & np.isfinite(self.returns_)  # not empty: needs_success (base class)
        r = self.returns_[ok]
        z = model_returns(r, cfg.regression.fit_hyperparameters)  # standardised when fitted (base.model_returns)
        if cfg.regression.fit_hyperparameters:  # the same points in any unit of the return
            reg = self._fitter.regression(self.X_[ok], z)
        else:
            reg = cfg.regression.build().fit(self.X_[ok], z)
        safety = self.safety_model()
        threshold = 1.0 - cfg.alpha

        def acquisition(X):
            mu, var = reg.predict(X)
            value = upper_confidence_bound(mu, var, cfg.kappa)
            return np.where(self.safe_probability(X, safety) >= threshold, value, -np.inf)

        x, value = maximize(acquisition, self.bounds, rng=self.rng, config=cfg.maximizer, extra=self.X_)
        if not np.isfinite(value):
            return StopReason.NO_IMPROVEMENT  # no candidate is safe enough
        if _stop(cfg.stop_rule, x, self.X_, cfg.stop_distance):
            return StopReason.CONVERGED
        return x
