"""g_R and g_S over ``(theta, c)``: one pair of GPs for every context seen, read at one context.

The black-box step of a contextual run keeps its optimizer (SEIB by default) unchanged: the
optimizer sees only theta, as in one scene, and asks its models for predictions at thetas. Here
those models are fitted on the joint inputs ``x = (theta, c)`` of every trial in every context
(the data of earlier scenes and this one), with the ARD squared exponential of Eq. 16 over the
joint box::

    k((theta, c), (theta', c')) = sf^2 exp(-|theta - theta'|^2_{l_theta} / 2) exp(-|c - c'|^2_{l_c} / 2)

which is the product of a kernel over theta and one over the context. Its length scales, signal
std and noise are MAP-fitted in the joint unit box exactly as in one scene
(:mod:`corl.gp.fitting`): ``l_c`` says how far a scene's data reaches into its neighbours. The
fitted model is then read as a function of theta alone at the current context ``c``
(:class:`ContextSlice`), which is all an acquisition needs; its length scales, failed points and
data rows are those of theta and of the current scene.

A fixed-hyperparameter preset (the paper's, in one scene's units) says nothing about how far
contexts correlate, so across contexts the hyperparameters are always fitted (the preset's
priors where it has them, else the defaults), a decision recorded in DESIGN.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl.errors import InputError
from corl.gp import SquaredExponential
from corl.gp.fitting import ClassifierPriors, HyperPrior, RegressionPriors, fit_classifier, fit_regression
from corl.problem import Bounds

__all__ = ["Anchor", "ContextData", "ContextSlice", "ContextualModels", "joint_bounds", "CONTEXT_LENGTHSCALE",
           "joint_lengthscale_priors"]

#: The length-scale prior of a context coordinate (unit box), for g_R and g_S alike: scenes across
#: half the box are alike unless the data say otherwise. Theta's priors (0.25 for g_R, 0.1 for g_S)
#: are short because the optimizer chooses theta and should step carefully into the unknown; it
#: cannot choose the context, and a short prior there would keep every scene's data to itself
#: (with 8 training scenes in 4-D, g_S's success probability in a new scene stayed below 0.5).
CONTEXT_LENGTHSCALE = HyperPrior(0.5, 0.75, 0.03, 3.0)


def joint_lengthscale_priors(theta_prior: HyperPrior, m: int, k: int) -> list[HyperPrior]:
    """Length-scale priors over ``(theta, c)``: theta's own, then :data:`CONTEXT_LENGTHSCALE`."""
    return [theta_prior] * m + [CONTEXT_LENGTHSCALE] * k


def joint_bounds(theta_bounds: Bounds, context_bounds: Bounds) -> Bounds:
    """The box of ``(theta, c)``: theta's box, then the context's, (m + k,)."""
    return Bounds(np.concatenate([theta_bounds.lower, context_bounds.lower]),
                  np.concatenate([theta_bounds.upper, context_bounds.upper]))


@dataclass(frozen=True, eq=False)
class ContextData:
    """Trials of the black-box step across contexts.

    Attributes
    ----------
    theta : (d, m) the thetas tried; context : (d, k) the context of each.
    success : (d,) bool; returns : (d,) float, NaN where no return was observed.
    """

    theta: np.ndarray
    context: np.ndarray
    success: np.ndarray
    returns: np.ndarray

    @classmethod
    def empty(cls, m: int, k: int) -> "ContextData":
        return cls(np.empty((0, m)), np.empty((0, k)), np.empty(0, dtype=bool), np.empty(0))

    def __post_init__(self) -> None:
        theta = np.asarray(self.theta, dtype=float)
        context = np.asarray(self.context, dtype=float)
        success = np.asarray(self.success, dtype=bool).reshape(-1)
        returns = np.asarray(self.returns, dtype=float).reshape(-1)
        d = len(success)
        if theta.ndim != 2 or context.ndim != 2 or len(theta) != d or len(context) != d or len(returns) != d:
            raise InputError(f"ContextData needs one row per trial: theta {theta.shape}, context {context.shape}, "
                             f"success {success.shape}, returns {returns.shape}")
        if np.any(success & ~np.isfinite(returns)):
            raise InputError("ContextData: every success needs a finite return")
        for name, value in (("theta", theta), ("context", context), ("success", success), ("returns", returns)):
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.success)

    def add(self, theta, context, success: bool, return_) -> "ContextData":
        """A copy with one more trial."""
        r = np.nan if return_ is None else float(return_)
        return ContextData(np.vstack([self.theta, np.reshape(theta, (1, -1))]),
                           np.vstack([self.context, np.reshape(context, (1, -1))]),
                           np.append(self.success, bool(success)), np.append(self.returns, r))

    def __add__(self, other: "ContextData") -> "ContextData":
        return ContextData(np.vstack([self.theta, other.theta]), np.vstack([self.context, other.context]),
                           np.concatenate([self.success, other.success]), np.concatenate([self.returns, other.returns]))

    def contexts(self) -> np.ndarray:
        """The distinct contexts, in the order first seen, (u, k)."""
        seen: list[np.ndarray] = []
        for c in self.context:
            if not any(np.array_equal(c, s) for s in seen):
                seen.append(c)
        return np.array(seen).reshape(-1, self.context.shape[1])


@dataclass(frozen=True, eq=False)
class Anchor:
    """The best policy learned in one context: ``context`` (k,), ``w`` (n,), ``theta`` (m,), its return."""

    context: np.ndarray
    w: np.ndarray
    theta: np.ndarray
    return_: float


class _SliceKernel:
    """The theta part of a joint kernel: what an acquisition reads (length scales, signal std)."""

    def __init__(self, kernel: SquaredExponential, m: int) -> None:
        ls = np.atleast_1d(np.asarray(kernel.lengthscales, dtype=float))
        self.lengthscales = np.full(m, ls[0]) if ls.size == 1 else ls[:m].copy()
        self.context_lengthscales = ls.copy() if ls.size == 1 else ls[m:].copy()
        self.signal_std = float(kernel.signal_std)


class ContextSlice:
    """A GP fitted over ``(theta, c)``, read as a function of theta at one context ``c`` (k,).

    Speaks what the acquisitions use of :class:`~corl.gp.GPRegression` and
    :class:`~corl.gp.GPClassifier`: ``predict``, ``predict_latent``, ``predict_latent_positive``,
    ``latent_mean_on_lattice``, ``kernel`` (theta's length scales), and ``X_`` / ``y_``, the rows
    of the current context (theta only). ``joint`` is the fitted model itself.
    """

    def __init__(self, joint, context: np.ndarray, m: int, X_here: np.ndarray, y_here: np.ndarray) -> None:
        self.joint, self.context, self.m = joint, np.asarray(context, dtype=float), int(m)
        self.kernel = _SliceKernel(joint.kernel, self.m)
        self.X_, self.y_ = np.asarray(X_here, dtype=float).reshape(-1, self.m), np.asarray(y_here, dtype=float)

    def _at(self, X) -> np.ndarray:
        X = np.asarray(X, dtype=float).reshape(-1, self.m)
        return np.hstack([X, np.broadcast_to(self.context, (len(X), len(self.context)))])

    def predict(self, X, **kw):
        return self.joint.predict(self._at(X), **kw)

    def predict_latent(self, X):
        return self.joint.predict_latent(self._at(X))

    def predict_latent_positive(self, X):
        return self.joint.predict_latent_positive(self._at(X))

    def predict_proba(self, X):
        return self.joint.predict_proba(self._at(X))

    def latent_mean_on_lattice(self, axes) -> np.ndarray:
        grids = np.meshgrid(*[np.asarray(a, dtype=float) for a in axes], indexing="ij")
        return self.predict_latent(np.stack([g.ravel() for g in grids], axis=1))[0]


class ContextualModels:
    """Fits g_R and g_S over ``(theta, c)`` for an optimizer over theta at context ``c``.

    Drop-in for :class:`corl.optimizers.gpconfig.ModelFitter` (an optimizer's ``models``): the
    optimizer passes its own data (this context), ``prior`` adds every other trial.

    Parameters
    ----------
    theta_bounds, context_bounds : the boxes; the joint unit box is theirs.
    prior : :class:`ContextData` of the other trials (earlier scenes, earlier starts here).
    context : (k,) the current context.
    regression_priors, classifier_priors, prior_mean : the fit's priors and g_S's prior mean.
    """

    def __init__(self, theta_bounds: Bounds, context_bounds: Bounds, prior: ContextData, context, *,
                 regression_priors: RegressionPriors = RegressionPriors(),
                 classifier_priors: ClassifierPriors = ClassifierPriors(), prior_mean: float = -7.0) -> None:
        self.bounds = joint_bounds(theta_bounds, context_bounds)
        self.m, self.k = theta_bounds.dim, context_bounds.dim
        self.context = np.asarray(context, dtype=float).reshape(self.k)
        if prior.theta.shape[1] != self.m or prior.context.shape[1] != self.k:
            raise InputError(f"prior data has theta {prior.theta.shape[1]} / context {prior.context.shape[1]} columns; "
                             f"the task has {self.m} / {self.k}")
        self.prior = prior
        self.regression_priors, self.classifier_priors = regression_priors, classifier_priors
        self.prior_mean = prior_mean
        self._warm: dict[str, np.ndarray | None] = {"regression": None, "classifier": None}
        self.fallback: dict[str, str] = {}
        self.last_regression = self.last_classifier = None  # the joint models of the latest fits

    @property
    def classifier_config(self):  # read by SEIB's far look with far_lengthscale (refused across contexts)
        raise InputError("SEIBConfig.far_lengthscale is not supported across contexts; leave it None")

    def _joint(self, X, extra_theta, extra_context) -> np.ndarray:
        X = np.asarray(X, dtype=float).reshape(-1, self.m)
        here = np.hstack([X, np.broadcast_to(self.context, (len(X), self.k))])
        return np.vstack([np.hstack([extra_theta, extra_context]), here])

    def _fit(self, kind: str, fit, keep: bool = True, **kw):
        """One MAP fit of ``kind`` ("regression" / "classifier") over the joint box, warm-started from
        the last one; the joint model is kept as ``last_<kind>`` (with ``keep``: else nothing changes)."""
        priors = self.regression_priors if kind == "regression" else self.classifier_priors
        res = fit(bounds=self.bounds, priors=priors, warm=self._warm[kind],
                  lengthscale_priors=joint_lengthscale_priors(priors.lengthscale, self.m, self.k), **kw)
        if keep:
            if not res.fallback:
                self._warm[kind] = res.log_params
            self.fallback[kind] = res.fallback
            setattr(self, f"last_{kind}", res.model)
        return res.model

    def return_spread(self, y) -> float:
        """The returns' spread for SEIB's margins (in the units of ``y``, this scene's successes): that of
        every scene's successes and ``y``. One scene's few returns say little of how far R varies;
        with one success its spread would be that return's size (corl.optimizers.safe.return_scale)."""
        from corl.optimizers.safe import return_scale

        p = self.prior
        return return_scale(np.concatenate([p.returns[p.success & np.isfinite(p.returns)], np.asarray(y, float)]))

    def regression(self, X, y, *, keep: bool = True):
        """g_R on this context's successes ``X`` (d, m), ``y`` (d,) and every other success."""
        p = self.prior
        ok = p.success & np.isfinite(p.returns)
        yj = np.concatenate([p.returns[ok], np.asarray(y, dtype=float)])
        if len(yj) == 0:
            return None
        model = self._fit("regression", fit_regression, keep, X=self._joint(X, p.theta[ok], p.context[ok]), y=yj)
        return ContextSlice(model, self.context, self.m, X, y)

    def classifier(self, X, s, *, keep: bool = True):
        """g_S on this context's points ``X`` (d, m), outcomes ``s`` (d,), and every other trial."""
        p = self.prior
        sj = np.concatenate([p.success, np.asarray(s, dtype=bool)])
        model = self._fit("classifier", fit_classifier, keep, X=self._joint(X, p.theta, p.context), s=sj,
                          prior_mean=self.prior_mean, previous=self.last_classifier)
        labels = np.where(np.asarray(s, dtype=bool), 1.0, -1.0)
        return ContextSlice(model, self.context, self.m, X, labels)
