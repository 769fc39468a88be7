"""corl's black-box methods built by name over a box, from a start point: :func:`make_optimizer`.

For users without a trajectory: the safe optimizer on its own. Every method comes out speaking
the :class:`~corl.optimizers.base.BlackBoxOptimizer` contract (``ask``, ``tell``, ``done``,
``stop_reason``, ``best``); its first trial is the start, and ``budget`` counts every trial, the
start included. :func:`corl.loop.optimize` is the loop around it.

The registry is a dict from name to builder; :func:`register_optimizer` adds one::

    @register_optimizer("MyPIBU")
    def _build(bounds, start, *, budget, rng, settings):
        return MyOptimizer(bounds, max_evals=budget, seed=rng, start=start)

The same builders make the black-box part of the paper's methods
(:func:`corl.methods.make_method`), with the paper's settings.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from corl import checks
from corl.acquisition import PIBUConfig, PIBUVariant
from corl.acquisition.safe_ei import SEIBConfig
from corl.errors import InputError
from corl.optimizers.base import START_RETRIES, BlackBoxOptimizer, as_point, as_rng
from corl.optimizers.bo import BOConfig, PIBUOptimizer, StopRule, UCBOptimizer
from corl.optimizers.gpconfig import (FITTED_CLASSIFIER, FITTED_REGRESSION, SYNTHETIC_CLASSIFIER,
                                      SYNTHETIC_REGRESSION, ClassifierConfig, RegressionConfig)
from corl.optimizers.sal import SALConfig, SALOptimizer
from corl.problem import Bounds

__all__ = ["OptimizerSettings", "OPTIMIZERS", "register_optimizer", "make_optimizer", "as_bounds"]

Builder = Callable[..., BlackBoxOptimizer]
OPTIMIZERS: dict[str, Builder] = {}

# Without settings, these fit their GP hyperparameters to the data and model returns units-free: the
# same trials in any unit of the return (the paper's fixed presets are corl.settings' PAPER_*).
FITTED_BY_DEFAULT = ("CORL", "SEIB", "CORL(budget)", "PIBU", "PIBU(budget)", "PIBU(literal)", "UCB", "SAL")
FAILURE_RETURN = -15.0  # the paper's constant cost of a failure, in the synthetic benchmark's units
BOX_LENGTHSCALE = 0.1  # GP length scales of a user's box: a tenth of its width per dimension


@checks.keywords()
@dataclass(frozen=True)
class OptimizerSettings:
    """Everything the black-box methods need besides the box, the start and the budget.

    Attributes
    ----------
    regression, classifier : the return GP g_R and the success GP g_S.
    failure_return : the score of a failure for the methods that ignore safety (UCB, CMA, PoWER), or
        None: UCB scores a failure one observed range below the worst success (units-free;
        :func:`~corl.optimizers.base.failure_score`), CMA and PoWER, which fit no GP, -15.
    ucb_kappa : UCB's exploration weight.
    cma_sigma0 : CMA-ES's initial step, a fraction of the box width.
    stop_distance : PIBU's and SAL's stop: the next point is this close to a sampled one.
    step_distance : UCB's and PIBU(literal)'s stop: the step ``||theta(d+1) - theta(d)||`` is this small.
    distance_scale : (m,) the unit the two distances are measured in per dimension, or None
        (theta's own units). SAL measures in theta's own units.
    sal : SAL's settings; None takes ``SALConfig(regression=regression)``.
    seib : CORL's (SEIB's) acquisition settings, e.g. ``SEIBConfig(far=False)`` never looks far
        past what it has tried before stopping (fewer trials and failures, no valley crossing).

    Notes
    -----
    The defaults are the paper's synthetic values, in the synthetic benchmark's units;
    :meth:`for_box` scales them to any box.
    """

    regression: RegressionConfig = SYNTHETIC_REGRESSION  # the paper's fixed values (Sec. VIII-A)
    classifier: ClassifierConfig = SYNTHETIC_CLASSIFIER
    failure_return: float | None = FAILURE_RETURN
    ucb_kappa: float = 2.0
    cma_sigma0: float = 0.3
    stop_distance: float = 1e-3
    step_distance: float = 3e-3
    distance_scale: tuple[float, ...] | None = None
    sal: SALConfig | None = None
    seib: SEIBConfig = field(default_factory=SEIBConfig)
    start_retries: int = START_RETRIES  # a start reported as failed is asked again this often (safe methods)
    confirm: int = 0  # trials that repeat the best at the end (CORL, PIBU): for noisy returns, before deploying
    label_noise: float = 0.0  # how often the success sensor errs, if known (CORL: a stop one failure decides is rechecked)
    return_noise: float | None = None  # a return reading's std, if known (CORL: edges mapped for gains beyond it)

    def __post_init__(self) -> None:  # every field checked here, as MethodSettings checks its own (corl.checks)
        for name, kind in (("regression", RegressionConfig), ("classifier", ClassifierConfig), ("seib", SEIBConfig),
                           ("sal", SALConfig)):
            value = getattr(self, name)
            if not isinstance(value, kind) and not (name == "sal" and value is None):
                where = {SEIBConfig: "corl", SALConfig: "corl.optimizers.sal"}.get(kind, "corl.settings")
                raise InputError(f"OptimizerSettings.{name} must be a {where}.{kind.__name__}"
                                 f"{' or None' if name == 'sal' else ''}, got {type(value).__name__}")

        def check(name, checker, *args, **limits):
            object.__setattr__(self, name, checker(f"OptimizerSettings.{name}", getattr(self, name), *args, **limits))

        if self.failure_return is not None:
            check("failure_return", checks.number)
        check("ucb_kappa", checks.number, low=0.0)
        check("cma_sigma0", checks.number, low=0.0, low_open=True)
        check("stop_distance", checks.number, low=0.0)
        check("step_distance", checks.number, low=0.0)
        if self.distance_scale is not None:
            check("distance_scale", checks.lengths)
            if not isinstance(self.distance_scale, tuple):
                object.__setattr__(self, "distance_scale", (self.distance_scale,))
        check("start_retries", checks.integer)
        check("confirm", checks.integer)
        object.__setattr__(self, "label_noise", checks.number(
            "OptimizerSettings.label_noise (how often the success sensor errs)", self.label_noise, low=0.0, high=0.5,
            high_open=True))
        if self.return_noise is not None:
            object.__setattr__(self, "return_noise", checks.number(
                "OptimizerSettings.return_noise (the std of a return reading, in its units)", self.return_noise, low=0.0))
        self.seib.check_classifier(self.classifier)  # far_lengthscale needs a fitted g_S: refused here, before a trial

    @classmethod
    def for_box(cls, bounds: Bounds, *, fitted: bool = False) -> "OptimizerSettings":
        """Settings in units of ``bounds``: GP length scales a tenth of the width per dimension,
        stopping distances a fraction of the width (0.1 % near a sampled point, 0.3 % per step).
        ``fitted``: GPs whose hyperparameters are fitted from the data instead (what "CORL" and
        "SEIB" get without settings)."""
        width = np.asarray(bounds.width, dtype=float)
        ls = tuple(float(v) for v in BOX_LENGTHSCALE * width)
        mean_width = float(np.exp(np.mean(np.log(width))))  # SAL's scalar settings: the geometric mean
        # Fixed GPs scaled to the box: the length scales a tenth of the width, the signal and noise
        # the paper's synthetic values (returns of order 1-10; "fitted" has no such assumption).
        regression = RegressionConfig(lengthscale=ls, signal_std=SYNTHETIC_REGRESSION.signal_std,
                                      noise_std=SYNTHETIC_REGRESSION.noise_std)
        sal = SALConfig(regression=regression, critical_distance=0.08 * mean_width,
                        safety_lengthscale=BOX_LENGTHSCALE * mean_width, stop_distance=1e-3 * mean_width)
        if fitted:  # units-free: GPs on standardised returns, failures scored relative to the successes
            return cls(regression=FITTED_REGRESSION, classifier=FITTED_CLASSIFIER, failure_return=None,
                       distance_scale=tuple(float(v) for v in width), sal=replace(sal, regression=FITTED_REGRESSION))
        return cls(regression=regression, classifier=ClassifierConfig(lengthscale=ls,
                                                                      signal_std=SYNTHETIC_CLASSIFIER.signal_std),
                   distance_scale=tuple(float(v) for v in width), sal=sal)

    def check_box(self, bounds: Bounds) -> "OptimizerSettings":
        """Refuse settings whose lengths do not fit ``bounds`` (settings for another box), before any trial;
        returns self."""
        m = bounds.dim
        self.regression.check_dimension(m, "OptimizerSettings.regression")
        self.classifier.check_dimension(m, "OptimizerSettings.classifier")
        if self.sal is not None:
            self.sal.regression.check_dimension(m, "OptimizerSettings.sal.regression")
        if self.distance_scale is not None and len(self.distance_scale) != m:
            raise InputError(f"OptimizerSettings.distance_scale has {len(self.distance_scale)} values but the box has "
                             f"{m} dimensions: settings for another box? (OptimizerSettings.for_box(box) makes them)")
        return self

    def bo(self, stop_rule: StopRule = StopRule.NEAR_SAMPLED) -> BOConfig:
        distance = self.stop_distance if stop_rule is StopRule.NEAR_SAMPLED else self.step_distance
        return BOConfig(self.regression, self.classifier, stop_rule=stop_rule, stop_distance=distance,
                        distance_scale=self.distance_scale)


def register_optimizer(name: str, *, replace: bool = False) -> Callable[[Builder], Builder]:
    """Decorator: ``builder(bounds, start, *, budget, rng, settings) -> BlackBoxOptimizer`` under ``name``.

    A built-in name ("CORL", "PIBU", ...) is refused unless ``replace=True``: every method of that
    name (``make_optimizer``, ``optimize`` and the paper's methods in ``make_method``) would then build yours.
    """
    checks.text("an optimizer name", name)
    checks.flag("register_optimizer(replace=...)", replace)
    if name in _BUILT_IN and not replace:
        raise InputError(f"{name!r} is one of corl's own optimizers; register yours under another name, or pass "
                         "replace=True to build yours wherever that name is used")

    def add(builder: Builder) -> Builder:
        OPTIMIZERS[name] = checks.function(f"the builder of optimizer {name!r}", builder, optional=False,
                                           what="(bounds, start, *, budget, rng, settings) -> BlackBoxOptimizer")
        return builder

    return add


_BUILT_IN: frozenset[str] = frozenset()  # the names registered below, when this module is loaded


@register_optimizer("PIBU")
def _pibu(bounds, start, *, budget, rng, settings):
    return PIBUOptimizer(bounds, settings.bo(), max_evals=budget, seed=rng, start=start, **_repeats(settings))


@register_optimizer("PIBU(budget)")  # PIBU without its stopping rule: it runs the whole budget
def _pibu_budget(bounds, start, *, budget, rng, settings):
    return PIBUOptimizer(bounds, settings.bo(StopRule.BUDGET), max_evals=budget, seed=rng, start=start,
                         **_repeats(settings))


@register_optimizer("PIBU(literal)")
def _pibu_literal(bounds, start, *, budget, rng, settings):
    return PIBUOptimizer(bounds, settings.bo(StopRule.SMALL_STEP), PIBUConfig(variant=PIBUVariant.LITERAL),
                         max_evals=budget, seed=rng, start=start)


@register_optimizer("UCB")
def _ucb(bounds, start, *, budget, rng, settings):
    return UCBOptimizer(bounds, settings.bo(StopRule.SMALL_STEP), kappa=settings.ucb_kappa,
                        failure_return=settings.failure_return, max_evals=budget, seed=rng, start=start)


@register_optimizer("SAL")
def _sal(bounds, start, *, budget, rng, settings):
    cfg = settings.sal if settings.sal is not None else SALConfig(regression=settings.regression)
    return SALOptimizer(bounds, cfg, max_evals=budget, seed=rng, start=start)


@register_optimizer("CMA")
def _cma(bounds, start, *, budget, rng, settings):
    from corl.optimizers.cmaes import CMAES, CMAESConfig

    return CMAES(bounds, start, CMAESConfig(sigma0=settings.cma_sigma0), failure_return=_fixed_failure(settings),
                 max_evals=budget, seed=rng, start=start)


@register_optimizer("PoWER")
def _power(bounds, start, *, budget, rng, settings):
    from corl.optimizers.power import PoWER, PoWERConfig

    return PoWER(bounds, start, PoWERConfig(), failure_return=_fixed_failure(settings), max_evals=budget, seed=rng,
                 start=start)


def _repeats(settings) -> dict:
    """The start's retries and the best's confirmations, for the methods that take them."""
    return {"start_retries": settings.start_retries, "confirm": settings.confirm}


def _fixed_failure(settings) -> float:
    """CMA's and PoWER's failure score: they fit no GP, so None (units-free for UCB) is the paper's -15."""
    return FAILURE_RETURN if settings.failure_return is None else settings.failure_return


@register_optimizer("CORL")  # the default: safe BO by SEIB on fitted GPs (corl.optimizers.safe)
@register_optimizer("SEIB")  # the same, by its acquisition's name (the black-box step of the CORL method)
def _seib(bounds, start, *, budget, rng, settings):
    from corl.optimizers.safe import SAFE_BO_CONFIG, SafeBOOptimizer

    config = replace(SAFE_BO_CONFIG, regression=settings.regression, classifier=settings.classifier)
    return SafeBOOptimizer(bounds, config, settings.seib, max_evals=budget, seed=rng, start=start,
                           label_noise=settings.label_noise, return_noise=settings.return_noise,
                           **_repeats(settings))


@register_optimizer("CORL(budget)")  # CORL that spends its whole budget (SafeBOOptimizer._spend), never below the band
def _seib_budget(bounds, start, *, budget, rng, settings):
    from corl.optimizers.safe import SAFE_BO_CONFIG, SafeBOOptimizer

    config = replace(SAFE_BO_CONFIG, regression=settings.regression, classifier=settings.classifier)
    return SafeBOOptimizer(bounds, config, settings.seib, max_evals=budget, seed=rng, start=start, spend_budget=True,
                           label_noise=settings.label_noise, return_noise=settings.return_noise,
                           **_repeats(settings))


_BUILT_IN = frozenset(OPTIMIZERS)


def as_bounds(bounds) -> Bounds:
    """A :class:`Bounds` from a Bounds or a pair ``(lower, upper)``, with a clear error for a flat box."""
    if isinstance(bounds, Bounds):
        return bounds
    try:
        lower, upper = bounds
        lower = np.atleast_1d(np.asarray(lower, dtype=float))
        upper = np.atleast_1d(np.asarray(upper, dtype=float))
    except (TypeError, ValueError):
        raise InputError(f"bounds must be a corl.Bounds or a pair (lower, upper) of (m,) arrays, got {bounds!r}") from None
    if lower.shape == upper.shape and lower.ndim == 1 and np.all(np.isfinite(lower)) and np.all(np.isfinite(upper)):
        flat = np.flatnonzero(~(lower < upper))
        if flat.size:
            raise InputError(
                f"the box has no width in coordinate(s) {flat.tolist()} (lower {lower[flat].tolist()}, upper "
                f"{upper[flat].tolist()}): give lower < upper, or leave a fixed coordinate out of theta")
    return Bounds(lower, upper)


def make_optimizer(name: str, bounds, start, *, budget: int = 50, seed=None,
                   settings: OptimizerSettings | None = None) -> BlackBoxOptimizer:
    """One of corl's black-box methods over ``bounds``, from ``start``, as an ask/tell optimizer.

    Parameters
    ----------
    name : a key of :data:`OPTIMIZERS`: "CORL" (the default: safe BO by SEIB, GPs fitted from the
        data; also "SEIB"), "PIBU", "PIBU(literal)", "PIBU(budget)", "UCB", "SAL", "CMA", "PoWER"
        (and any registered later).
    bounds : :class:`Bounds` or ``(lower, upper)``, (m,) each, lower < upper.
    start : (m,) inside the box: the first trial. The safe methods (PIBU, SAL) grow the safe set
        from it, so it should be a point known to succeed.
    budget : trials in all, the start included (>= 1).
    seed : an integer >= 0, a numpy Generator or None.
    settings : :class:`OptimizerSettings`; None takes :meth:`OptimizerSettings.for_box` (with
        ``fitted=True`` for "CORL" and "SEIB"). To change one thing, start from that:
        ``replace(OptimizerSettings.for_box(box, fitted=True), seib=SEIBConfig(far=False))``.

    Raises
    ------
    InputError : unknown name, a flat box, a start outside it (or not numbers), a budget < 1, a
        seed that is not an integer >= 0 (or a Generator, or None), settings of another type or for a
        box of another dimension.
    """
    if not isinstance(name, str) or name not in OPTIMIZERS:
        raise InputError(f"unknown optimizer {name!r}; choose one of {', '.join(OPTIMIZERS)}")
    box = as_bounds(bounds)
    try:
        x0 = as_point(start, box, name=name, what="start")
    except InputError as exc:
        raise InputError(f"the start is not a point of the box: {exc}") from None
    budget = checks.integer("budget (trials in all, the start included)", budget, low=1)
    rng = as_rng(seed)
    if settings is None:  # corl's default (CORL, SEIB) learns its GPs from the data
        settings = OptimizerSettings.for_box(box, fitted=name in FITTED_BY_DEFAULT)
    elif not isinstance(settings, OptimizerSettings):
        raise InputError(f"settings must be a corl.OptimizerSettings (e.g. OptimizerSettings.for_box(box)), got "
                         f"{type(settings).__name__}")
    else:
        settings.check_box(box)
    return OPTIMIZERS[name](box, x0, budget=budget, rng=rng, settings=settings)
