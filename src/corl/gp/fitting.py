"""MAP hyperparameters for g_R and g_S in normalised units, safe with few points.

Both GPs are fitted in the unit box (``U = Bounds.to_unit(X)``); g_R on standardised returns
``z = (y - y_mean) / y_scale``. There every hyperparameter has a weak log-normal prior and hard
bounds that do not depend on the task's units, so one set of priors serves every user's task.
The fitted values are then mapped back to theta units exactly:

    k_theta(x, x') = k_unit(u, u')  with  l_theta = l_unit * width          (ARD, Eq. 16)
    g_R(x) = y_mean + y_scale * g_unit(u):  m0 = y_mean, sf = sf_unit * y_scale,
                                            sigma = sigma_unit * y_scale

so the returned model is an ordinary :class:`GPRegression` / :class:`GPClassifier` in theta units
(acquisitions see no difference). When the data cannot identify the hyperparameters (too few
successes, all returns equal, all labels equal) or the optimizer fails, the prior medians are
used (``FitResult.fallback`` says why). Each fit starts L-BFGS-B from the previous fit's values
(``warm``) and runs a few iterations with analytic gradients: GPML eq. 5.9 for g_R, the Laplace
approximation's GPML Alg. 5.1 for g_S.

g_S's length-scale prior (median 0.1 of the box) is too wide for a safe set much thinner than
that: failures all around a known-safe start are then explained by calling the start a lucky
success, and the search stops there. So g_S is also fitted under a *thin* prior whose median is
read off the data (:func:`thin_set_prior`: the closest failure to a success, the successes' own
spread) and that fit is kept when the data favour it (:data:`THIN_ODDS`), or while there are too
few successes to tell (:data:`THIN_EARLY`). ``ClassifierPriors(thin=False)`` turns this off.

Glossary
--------
U        : inputs in the unit box, (d, m)
z        : standardised returns, (d,)
v        : log hyperparameters in unit-box units: ``[log l_1..l_m, log sf(, log sigma)]``
prior    : ``log p(v) = sum_j -1/2 ((v_j - log median_j) / spread_j)^2`` (+ const)
MAP      : ``argmax_v log p(y | X, v) + log p(v)`` within the bounds
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from corl.errors import CorlError, InputError
from corl.gp.classification import GPClassifier, LaplaceConvergenceWarning, labels_to_pm1
from corl.gp.kernels import SquaredExponential
from corl.gp.regression import GPRegression

__all__ = ["HyperPrior", "RegressionPriors", "ClassifierPriors", "FitResult", "fit_regression", "fit_classifier",
           "standardisation"]


@dataclass(frozen=True)
class HyperPrior:
    """Log-normal prior ``log x ~ N(log median, spread^2)`` truncated to ``[low, high]``."""

    median: float
    spread: float
    low: float
    high: float

    def __post_init__(self) -> None:
        vals = (self.median, self.spread, self.low, self.high)
        if not all(np.isfinite(v) and v > 0 for v in vals) or not self.low <= self.median <= self.high \
                or self.low >= self.high:
            raise InputError(f"a hyperparameter prior needs 0 < low <= median <= high and spread > 0, got {self}")


@dataclass(frozen=True)
class RegressionPriors:
    """Priors of g_R in the unit box with standardised returns; medians are the fallback values."""

    lengthscale: HyperPrior = HyperPrior(0.25, 0.75, 0.03, 3.0)
    signal_std: HyperPrior = HyperPrior(1.0, 0.75, 0.1, 10.0)
    noise_std: HyperPrior = HyperPrior(0.05, 1.0, 1e-3, 1.0)
    min_points: int = 3  # fewer successes than this: no fit, prior medians
    max_iter: int = 20  # L-BFGS-B iterations per fit (warm-started)

    def __post_init__(self) -> None:
        if self.min_points < 2 or self.max_iter < 1:
            raise InputError(f"min_points must be >= 2 and max_iter >= 1, got {self.min_points}, {self.max_iter}")


@dataclass(frozen=True)
class ClassifierPriors:
    """Priors of g_S's kernel in the unit box (latent units); the prior mean stays fixed."""

    lengthscale: HyperPrior = HyperPrior(0.1, 0.75, 0.03, 3.0)  # short: small first steps into the unknown
    signal_std: HyperPrior = HyperPrior(10.0, 0.5, 2.0, 50.0)
    max_iter: int = 20
    thin: bool = True  # the length-scale prior follows a safe set thinner than it (:func:`thin_set_prior`)

    def __post_init__(self) -> None:
        if self.max_iter < 1:
            raise InputError(f"max_iter must be >= 1, got {self.max_iter}")
        if not isinstance(self.thin, (bool, np.bool_)):
            raise InputError(f"ClassifierPriors.thin must be True or False, got {self.thin!r}")


@dataclass(frozen=True, eq=False)
class FitResult:
    """A model fitted in theta units and the unit-box log hyperparameters to warm-start from.

    Attributes
    ----------
    model : fitted :class:`GPRegression` or :class:`GPClassifier` (theta units).
    log_params : (p,) unit-box ``v`` used (fitted, or the prior medians on fallback).
    fallback : empty when fitted, else why the prior medians were used.
    """

    model: object
    log_params: np.ndarray
    fallback: str = ""
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# The MAP search
# ---------------------------------------------------------------------------------------------
def _medians(priors: list[HyperPrior]) -> np.ndarray:
    return np.log([p.median for p in priors])


def _log_prior(v: np.ndarray, priors: list[HyperPrior]) -> tuple[float, np.ndarray]:
    """Log-normal log density (up to a constant) and its gradient in ``v``, (p,)."""
    mu = _medians(priors)
    s2 = np.array([p.spread for p in priors]) ** 2
    r = v - mu
    return float(-0.5 * np.sum(r * r / s2)), -r / s2


#: L-BFGS-B stops once every projected gradient component is below this, in nats per unit of log
#: hyperparameter: converged for any prediction. A warm start sits there already; scipy's default
#: (1e-5) then spent up to 30 evaluations in a line search against rounding noise (g_R at 100 points).
_GTOL = 1e-3


def _map(lml, v0: np.ndarray, priors: list[HyperPrior], max_iter: int) -> np.ndarray:
    """``argmax_v lml(v) + log p(v)`` by L-BFGS-B from ``v0`` within the priors' bounds; None if it fails."""
    from scipy import optimize  # only fitting needs it

    lo = np.log([p.low for p in priors])
    hi = np.log([p.high for p in priors])

    def negative(v):
        try:
            value, grad = lml(v)
        except CorlError:
            return np.inf, np.zeros_like(v)
        prior, dprior = _log_prior(v, priors)
        total = value + prior
        if not np.isfinite(total) or not np.all(np.isfinite(grad)):
            return np.inf, np.zeros_like(v)
        return -total, -(grad + dprior)

    start = np.clip(v0, lo, hi)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LaplaceConvergenceWarning)
        res = optimize.minimize(negative, start, jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)),
                                options={"maxiter": int(max_iter), "gtol": _GTOL})
    if not np.isfinite(res.fun) or not np.all(np.isfinite(res.x)):
        return None
    f_start, _ = negative(start)
    return res.x if res.fun <= f_start else start


def _map_or_medians(fit, v0: np.ndarray, priors: list[HyperPrior], max_iter: int) -> tuple[np.ndarray, str]:
    """Fit a model (``fit()`` returns it) and find its MAP hyperparameters from ``v0``.

    Returns ``(v, "")``, or the priors' medians and the reason when the fit or the search fails.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LaplaceConvergenceWarning)
            model = fit()
        found = _map(lambda w: model.log_marginal_likelihood(w, eval_gradient=True), v0, priors, max_iter)
    except CorlError:
        found = None
    if found is None:
        return _medians(priors), "marginal likelihood optimization failed"
    return found, ""


def _warm_start(warm, priors: list[HyperPrior]) -> np.ndarray:
    v = _medians(priors)
    if warm is not None:
        w = np.asarray(warm, dtype=float).reshape(-1)
        if w.shape == v.shape and np.all(np.isfinite(w)):
            v = w
    return v


# ---------------------------------------------------------------------------------------------
# g_R
# ---------------------------------------------------------------------------------------------
_LARGEST_SCALE = 1e150  # a GP's signal std up to this has a finite square, with room for the products on it


def _mean_and_spread(y: np.ndarray) -> tuple[float, float]:
    """Mean and standard deviation of ``y`` (d,); (0, 0) for no data. Past 1e150 (where ``y^2``
    and even a sum overflow) both are taken of ``y / max|y|`` and scaled back."""
    if not y.size:
        return 0.0, 0.0
    top = float(np.max(np.abs(y)))
    if top <= _LARGEST_SCALE:
        return float(np.mean(y)), float(np.std(y))
    u = y / top
    return top * float(np.mean(u)), top * float(np.std(u))


def standardisation(y) -> tuple[float, float]:
    """``(mean, scale)`` that standardise returns ``y`` (d,): ``z = (y - mean) / scale``.

    ``scale`` is the standard deviation; with one point (or equal returns) there is no spread, and
    the return's own magnitude (1 at 0) sets the scale, so that a later change of units changes nothing.
    """
    mean, spread = _mean_and_spread(np.asarray(y, dtype=float).reshape(-1))
    tiny = 1e-12 * max(1.0, abs(mean))
    return mean, (spread if spread > tiny else (abs(mean) if abs(mean) > 0 else 1.0))


def _lengthscale_priors(default: HyperPrior, m: int, given) -> list[HyperPrior]:
    """One length-scale prior per input dimension: ``given`` (m,) or ``default`` for every one."""
    if given is None:
        return [default] * m
    given = list(given)
    if len(given) != m or not all(isinstance(p, HyperPrior) for p in given):
        raise InputError(f"lengthscale_priors needs one HyperPrior per input dimension ({m}), got {len(given)}")
    return given


def fit_regression(X, y, bounds, priors: RegressionPriors = RegressionPriors(), warm=None, *,
                   lengthscale_priors=None) -> FitResult:
    """MAP fit of g_R (ARD squared exponential, Gaussian noise, constant mean = mean of y).

    Parameters
    ----------
    X : (d, m) successful thetas inside ``bounds``; y : (d,) their returns.
    bounds : :class:`corl.problem.Bounds` of theta (the unit box is defined by it).
    priors : :class:`RegressionPriors` in unit-box, standardised units.
    warm : (m + 2,) unit-box log hyperparameters of the previous fit, or None.
    lengthscale_priors : (m,) :class:`HyperPrior` per dimension in place of ``priors.lengthscale``
        (e.g. longer ones for a context, :mod:`corl.contexts.models`), or None.

    Returns
    -------
    FitResult with a fitted :class:`GPRegression` in theta units.
    """
    X = np.asarray(X, dtype=float).reshape(-1, bounds.dim)
    y = np.asarray(y, dtype=float).reshape(-1)
    if X.shape[0] != y.shape[0]:
        raise InputError(f"X has {X.shape[0]} rows but y has {y.shape[0]} entries; one per point")
    m = bounds.dim
    plist = _lengthscale_priors(priors.lengthscale, m, lengthscale_priors) + [priors.signal_std, priors.noise_std]
    U = bounds.to_unit(X)
    # Standardise: z = (y - mean) / scale. One point (or equal returns) has no spread; then the
    # return's own magnitude sets the scale so that a later change of units changes nothing.
    mean, scale = standardisation(y)
    if scale * priors.signal_std.high > _LARGEST_SCALE:  # sf = sf_unit * scale is squared in every kernel
        raise InputError(f"returns as large as {np.max(np.abs(y)):.3g} overflow a GP in their own units (its "
                         f"variance would pass 1e308): divide them by a constant first (corl's optimizers "
                         f"divide returns beyond 1e100 by a power of two)")
    z = (y - mean) / scale

    v, reason = _warm_start(warm, plist), ""
    if y.size < priors.min_points:
        reason, v = f"{y.size} successful point(s) < {priors.min_points}", _medians(plist)
    elif _mean_and_spread(y)[1] <= 1e-12 * max(1.0, abs(mean)):
        reason, v = "all returns equal", _medians(plist)
    else:
        gp = GPRegression(SquaredExponential(np.exp(v[:m]), np.exp(v[m])), float(np.exp(v[m + 1])))
        v, reason = _map_or_medians(lambda: gp.fit(U, z), v, plist, priors.max_iter)
    kernel = SquaredExponential(np.exp(v[:m]) * bounds.width, float(np.exp(v[m])) * scale)
    model = GPRegression(kernel, float(np.exp(v[m + 1])) * scale, prior_mean=mean).fit(X, y)
    return FitResult(model, v, reason, {"scale": scale})


# ---------------------------------------------------------------------------------------------
# g_S
# ---------------------------------------------------------------------------------------------
#: A failure at distance d from the nearest success (unit box) says the safe set may be as thin
#: as d there: g_S's thin length-scale prior has median ``THIN_PER_FAILURE * d``, and its band,
#: where the next trial goes, lies well inside d: each failure by the start shrinks the step several
#: times (on the suite's three seen thin sets 0.25 failed 5.8, 3.9 and 4.0 times per run, 0.5 failed
#: 6.0, 6.2 and 5.6 times, and the wide prior alone 9.7, 8.6 and 6.7).
THIN_PER_FAILURE = 0.25
#: ... unless the successes themselves spread wider: ``THIN_PER_SPREAD`` times their smallest
#: principal standard deviation (successes filling a set evenly keep the default prior once the set
#: is about 1.75 times the default median wide).
THIN_PER_SPREAD = 2.0
#: The smallest median: a safe set 0.2 % of the box thick (below it, a set is a wall of failures).
THIN_FLOOR = 0.002
#: Past :data:`THIN_EARLY` successes the thin prior's fit is kept only if its log posterior (Laplace
#: evidence plus log prior) beats the wide one's by this many nats: the prior odds against a thin
#: set, whose median was read off the data. On a wide set it then never wins (the suite's 42
#: problems: the same runs as without the rule, on the 8 where it was checked).
THIN_ODDS = 1.0
#: With at most this many successes the thin prior is taken without weighing: the start and one
#: more cannot tell a thin set from a wide one (weighed, the wide prior won until four to six
#: failures around the start had shown it wrong), and a wrong guess of "wide" costs a failure.
#: Guessing "thin" there costs a wide set a few short steps: 689 optima found on the suite's 42
#: problems against 696, at 3.17 failures per run against 3.24.
THIN_EARLY = 2


def thin_set_prior(U, y, prior: HyperPrior) -> HyperPrior:
    """g_S's length-scale prior for data ``U`` (d, m) in the unit box, labels ``y`` (+-1): ``prior``,
    or one whose median is ``max(THIN_PER_FAILURE * d_f, THIN_PER_SPREAD * s_min, THIN_FLOOR)``
    where that is smaller than ``prior``'s.

    ``d_f`` is the smallest distance from a failure to its nearest success, ``s_min`` the smallest
    principal standard deviation of the successes (0 with fewer than m + 1). With no failure the
    prior is unchanged; a safe set far thinner than the box's tenth (the default median) is then
    followed down to :data:`THIN_FLOOR` instead of being covered by one wide bump around the start,
    whose edge would keep proposing failures all around it. The lower bound follows the median
    (a third of it, 1.5 spreads below).
    """
    ok, bad = U[y > 0], U[y < 0]
    if not len(ok) or not len(bad):
        return prior
    d_f = float(np.min(np.linalg.norm(bad[:, None, :] - ok[None], axis=2)))
    s_min = 0.0
    if len(ok) > U.shape[1]:
        s_min = float(np.linalg.svd(ok - ok.mean(axis=0), compute_uv=False)[-1]) / np.sqrt(len(ok))
    median = max(THIN_PER_FAILURE * d_f, THIN_PER_SPREAD * s_min, THIN_FLOOR)
    if median >= prior.median:
        return prior
    return HyperPrior(median, prior.spread, min(prior.low, median / 3.0), prior.high)


def _unit_classifier(v: np.ndarray, prior_mean: float) -> GPClassifier:
    """An unfitted g_S in the unit box with log hyperparameters ``v = [log l_1..l_m, log sf]``."""
    return GPClassifier(SquaredExponential(np.exp(v[:-1]), float(np.exp(v[-1]))), prior_mean, warm_start=False)


def _classifier_map(U, y, prior_mean: float, v0: np.ndarray, plist: list[HyperPrior], max_iter: int):
    clf = _unit_classifier(v0, prior_mean)
    return _map_or_medians(lambda: clf.fit(U, y), v0, plist, max_iter)


def _log_posterior(U, y, prior_mean: float, v: np.ndarray, plist: list[HyperPrior]) -> float:
    """Laplace log evidence of g_S's data at log hyperparameters ``v`` plus their log prior (-inf if it fails)."""
    clf = _unit_classifier(v, prior_mean)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", LaplaceConvergenceWarning)
            clf.fit(U, y)
            value = float(clf.log_marginal_likelihood(v, eval_gradient=True)[0])
    except CorlError:
        return -np.inf
    # two log-normal priors of one spread share their Gaussian constant; their truncations differ (the
    # thin one's lower bound is lower), which is left out: it counts about 0.02 nats per dimension
    # against the thin prior, on top of THIN_ODDS. A comparison of the two modes, not of the evidence.
    return value + _log_prior(v, plist)[0] if np.isfinite(value) else -np.inf


def fit_classifier(X, s, bounds, prior_mean: float, priors: ClassifierPriors = ClassifierPriors(),
                   warm=None, previous: GPClassifier | None = None, *, lengthscale_priors=None) -> FitResult:
    """MAP fit of g_S's kernel with the Laplace marginal likelihood (GPML eq. 3.32, Alg. 5.1).

    The constant prior mean stays fixed: it encodes "unexplored regions fail" and would drift up
    to "everything succeeds" on a run of successes.

    Parameters
    ----------
    X : (d, m) thetas inside ``bounds``; s : (d,) outcomes (bool, {0, 1} or {-1, +1}).
    bounds : :class:`corl.problem.Bounds` of theta.
    prior_mean : constant prior mean of the latent function.
    priors : :class:`ClassifierPriors` in unit-box units.
    warm : (m + 1,) unit-box log hyperparameters of the previous fit, or None.
    previous : the previous fitted classifier; its Laplace mode warm-starts the Newton search.
    lengthscale_priors : (m,) :class:`HyperPrior` per dimension in place of ``priors.lengthscale``, or None
        (the caller's own priors, e.g. over theta and a context: no thin prior then).

    Returns
    -------
    FitResult with a fitted :class:`GPClassifier` in theta units.
    """
    X = np.asarray(X, dtype=float).reshape(-1, bounds.dim)
    y = labels_to_pm1(s)
    if X.shape[0] != y.shape[0]:
        raise InputError(f"X has {X.shape[0]} rows but s has {y.shape[0]} entries; one per point")
    m = bounds.dim
    U = bounds.to_unit(X)
    plist = _lengthscale_priors(priors.lengthscale, m, lengthscale_priors) + [priors.signal_std]
    v, reason = _warm_start(warm, plist), ""
    if y.size == 0 or np.all(y == y[0]):
        reason, v = "all outcomes equal" if y.size else "no data", _medians(plist)
    else:
        v, reason = _classifier_map(U, y, prior_mean, v, plist, priors.max_iter)
        thin = priors.lengthscale  # the caller's own per-dimension priors (lengthscale_priors) are kept as given
        if priors.thin and lengthscale_priors is None:
            thin = thin_set_prior(U, y, priors.lengthscale)
        if thin is not priors.lengthscale:  # might the safe set be thinner than the prior says?
            tlist = [thin] * m + [priors.signal_std]
            start = np.concatenate([_medians(tlist)[:m], v[m:]])
            vt, rt = _classifier_map(U, y, prior_mean, start, tlist, priors.max_iter)
            early = np.sum(y > 0) <= THIN_EARLY  # too few successes to weigh the two: the cautious one
            if not rt and (early or reason or _log_posterior(U, y, prior_mean, vt, tlist) - THIN_ODDS
                           > _log_posterior(U, y, prior_mean, v, plist)):
                v, reason = vt, ""
    kernel = SquaredExponential(np.exp(v[:m]) * bounds.width, float(np.exp(v[m])))
    model = GPClassifier(kernel, prior_mean)
    if previous is not None and hasattr(previous, "a_"):  # reuse the last mode as the Newton start
        model.a_, model.X_ = previous.a_, previous.X_
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LaplaceConvergenceWarning)
        model.fit(X, y)
    return FitResult(model, v, reason)
