"""The one interface every black-box optimizer speaks: ``ask``, ``tell``, ``done``, ``stop_reason``, ``best``.

PIBU, UCB, SAL, CMA-ES and PoWER all implement it, over ``theta`` inside CORL or over the full
``w`` as baselines. The CORL learner speaks the same protocol with :class:`corl.problem.Proposal`.

The stopping contract
---------------------
* The next point, or the decision to stop, is worked out once, lazily: by whichever of
  :attr:`done`, :attr:`stop_reason` or :meth:`ask` is read first after a ``tell``, and cached.
  ``ask`` returns the cached point, so ``while not opt.done: x = opt.ask(); opt.tell(x, f(x))``
  fits each GP once per trial and never sees an exception when the method converges.
* :attr:`stop_reason` (a :class:`StopReason`, None while running) says why it stopped.
  ``ask`` after a stop is a misuse and raises :class:`~corl.errors.StateError`.
* ``max_evals`` counts every point told (the start and any data told up front included).
* A told point *answers* the proposal when every coordinate lies within
  ``answer_tolerance`` (0.5 %) of the box width of it: a robot operator who types the asked theta
  with four decimals answers it. A proposal handed out by ``ask`` and not answered stays pending
  (a trial is never silently skipped); one worked out but not yet handed out is dropped when
  other data arrives, and worked out again from all the data.
* Every stop but the budget is a function of the data: a ``tell`` after a stop lets the method
  decide again (e.g. a successful point told after an all-failure history).
* Each asked point is told once: a ``tell`` that answers the point told last, with no ``ask``
  since, is refused (:class:`~corl.errors.StateError`, nothing recorded). A point that answers
  nothing asked is data and always welcome (a demonstration, data told up front, another
  method's trials).
* ``max_pending = K > 1`` (K robots): ``ask()`` hands out a new point while fewer than K are out, each
  decided with the others pending (:attr:`pending_`); tells come in any order. A repeat of a pending
  point, a stop or the budget while trials are out is no trial yet: :attr:`ready` is False until a tell.
* Returns reach the models in units where they cannot overflow: returns beyond
  :data:`MODEL_RANGE` in magnitude are divided by a power of two first (:func:`model_scale`), so
  any finite return, 1e300 included, keeps the method asking.
"""

from __future__ import annotations

import enum
import math
from abc import ABC, abstractmethod

import numpy as np

from corl.errors import InputError, StateError
from corl.problem import Bounds, Outcome, check_theta

__all__ = ["BlackBoxOptimizer", "StopReason", "as_outcome", "as_point", "as_rng", "score_of", "failure_score",
           "model_returns",
           "model_scale",
           "ANSWER_TOLERANCE", "MODEL_RANGE"]

ANSWER_TOLERANCE = 5e-3  # a told point answers the proposal within this fraction of the box width
#: A start reported as failed is asked again this many times before a safe method gives up on it: one
#: wrong reading of a success sensor (a latch switch, a vision check) must not end a run. Twice, not
#: once: with 5 % of readings wrong, two wrong readings in a row end one run in 400 (about 3 of the
#: safe-BO suite's 1,260 runs at --flip 0.05; valley-1d's start 6 was one); three in a row, one in 8,000.
START_RETRIES = 2
#: Returns up to this magnitude reach the models as told. Larger ones are divided by a power of two
#: (exact, :func:`model_scale`): a GP squares its returns' scale (signal variance, ``r @ alpha``),
#: which overflows beyond about 1e154; 1e100 leaves room for the products on top of that.
MODEL_RANGE = 1e100


class StopReason(str, enum.Enum):
    """Why an optimizer or a learner stopped (its ``stop_reason``; None while it runs)."""

    BUDGET = "budget"  # the trial budget is spent
    CONVERGED = "converged"  # the method's own stopping rule (near a sampled point, small step, tolx, ...)
    NO_IMPROVEMENT = "no_improvement"  # no point is worth a trial: the acquisition is zero / nothing is safe enough
    NO_SAFE_POINT = "no_safe_point"  # no successful trial yet: a safe method has nothing to expand from
    MAX_ROUNDS = "max_rounds"  # CORL: Algorithm 1 ran its ``max_rounds`` rounds
    ERROR = "error"  # a learner: an exception ended the run (it was raised to the caller)


_EXPLAIN = {
    StopReason.BUDGET: "its trial budget is spent",
    StopReason.CONVERGED: "its stopping rule fired (the next point would repeat a sampled one)",
    StopReason.NO_IMPROVEMENT: "no point is worth a trial (no likely improvement, no uncertain safe boundary)",
    StopReason.NO_SAFE_POINT: "every trial told so far failed, so a safe method has nothing to expand from; "
                              "tell a point known to succeed (e.g. the start) and ask again",
    StopReason.MAX_ROUNDS: "Algorithm 1 ran all its rounds",
    StopReason.ERROR: "an exception ended the run",
}


def model_returns(values: np.ndarray, fitted: bool) -> np.ndarray:
    """What a GP over returns (or scores) ``values`` (d,) is fitted on.

    Fitted hyperparameters (``fitted``): the standardised values ``(v - mean) / scale``
    (:func:`corl.gp.fitting.standardisation`), so that every number the method then compares (the
    best return, PI's and UCB's variance floors) is in the same units whatever the return's: the
    method proposes the same trials under ``a R + b``. Fixed hyperparameters (the paper's presets) are
    in the return's units: the values as they are, divided by :func:`model_scale` past MODEL_RANGE.
    """
    v = np.asarray(values, dtype=float)
    if fitted:
        from corl.gp.fitting import standardisation

        mean, scale = standardisation(v)
        with np.errstate(over="ignore"):
            z = (v - mean) / scale
        return z if np.all(np.isfinite(z)) else v / scale - mean / scale  # v - mean past 1.8e308: scale first
    return v / model_scale(v)


def failure_score(returns: np.ndarray, failure_return: float | None) -> float:
    """The score a safety-blind method models a failure with: ``failure_return``, or with None (fitted
    GPs: units-free) one observed range below the worst success, ``min R - (max R - min R)``.

    ``returns`` (d,) are the successful returns so far. While they hold fewer than two distinct
    values, the gap is ``|min R|`` (1 at 0): with one value and the failures' one, the standardised
    data a fitted GP sees is the same whatever the gap. So under ``a R + b`` (a > 0) the scores move
    along: a method on fitted GPs proposes the same points in any unit of the return.
    """
    if failure_return is not None:
        return float(failure_return)
    r = np.asarray(returns, dtype=float)
    r = r[np.isfinite(r)]
    if r.size == 0:
        return 0.0  # nothing succeeded: every score is this one, and standardised it is 0 anyway
    low, high = float(np.min(r)), float(np.max(r))
    gap = high - low if high > low else (abs(low) or 1.0)
    return max(low - gap, -float(np.finfo(float).max))  # a range of +-1.7e308 overflows: the lowest float


def score_of(outcome: Outcome, failure_return: float) -> float:
    """The scalar a method that ignores safety maximises: ``R`` on success, ``failure_return`` else."""
    return float(outcome.return_) if outcome.success else float(failure_return)


def model_scale(values) -> float:
    """The power of two returns ``values`` (d,) are divided by before they reach a model.

    1.0 while every finite value lies within :data:`MODEL_RANGE` (so the usual runs are untouched,
    bit for bit); else the smallest power of two that brings the largest magnitude within it.
    Dividing by a power of two is exact, and a GP fitted to standardised returns (``CORL``) proposes
    the same points in either unit, bit for bit; a GP with fixed hyperparameters (the paper's PIBU,
    UCB, SAL) was not made for returns past 1e100 in any unit, and now at least keeps proposing.
    """
    v = np.asarray(values, dtype=float)
    v = np.abs(v[np.isfinite(v)])
    top = float(np.max(v)) if v.size else 0.0
    if top <= MODEL_RANGE:
        return 1.0
    return math.ldexp(1.0, math.frexp(top / MODEL_RANGE)[1])  # 2^e > top / MODEL_RANGE


def as_rng(seed) -> np.random.Generator:
    """A Generator from ``seed``: an integer >= 0, a :class:`numpy.random.Generator` (used as it is) or
    None (fresh entropy); anything else is an :class:`~corl.errors.InputError`."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is not None and (isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer))
                             or seed < 0):
        raise InputError(f"seed must be an integer >= 0, a numpy Generator or None, got {type(seed).__name__} "
                         f"{seed!r:.40}")
    return np.random.default_rng(seed)


def as_point(x, bounds: Bounds, *, name: str, what: str = "x") -> np.ndarray:
    """``x`` as a point (m,) of ``bounds``, or :class:`~corl.errors.InputError` naming ``what``.

    :func:`corl.problem.check_theta`, with a value that is not numbers at all (a string, a dict)
    refused in one line too.
    """
    try:
        if x is None:  # not NaN: None is no number at all
            raise TypeError
        return check_theta(x, bounds, task=name)
    except InputError:
        raise
    except (TypeError, ValueError):
        raise InputError(f"{what} must be {bounds.dim} numbers (a point of the box), got "
                         f"{type(x).__name__} {x!r:.60}") from None


_MISSING = object()  # tell(x) without an outcome


def _told(x, outcome):
    """``outcome``, or InputError for ``tell(x)`` without one (a learner's tell takes the outcome alone)."""
    if outcome is _MISSING:
        raise InputError(f"an optimizer's tell takes the point and its outcome, tell(x, outcome); got only "
                         f"{type(x).__name__} {x!r:.40} (a learner's tell(outcome) takes the outcome alone)")
    return outcome


def as_outcome(value) -> Outcome:
    """An :class:`Outcome` from an Outcome or a tuple ``(success, return)`` / ``(success, return, info)``.

    A NaN or infinite return, a success without a return or a non-boolean success raise
    :class:`~corl.errors.InputError` (from :class:`Outcome`).
    """
    if isinstance(value, Outcome):
        return value
    if isinstance(value, tuple) and len(value) in (2, 3):
        try:
            return Outcome(*value)
        except OverflowError:  # an int past float's range (10**400): Outcome's float() overflows
            raise InputError(f"the return must be a finite number, got one too large for a float: "
                             f"{value[1]!r:.40}") from None
    raise InputError(f"an outcome must be a corl.Outcome or a tuple (success, return), got {type(value).__name__}: "
                     f"{value!r}")


class BlackBoxOptimizer(ABC):
    """Maximises a black-box return over a box, one trial at a time.

    Subclasses implement :meth:`_propose` (and :meth:`_observe`, :meth:`_withdraw` if they keep
    state); this base class keeps the data, validates input, caches the next decision and guards
    the ask/tell order (see the module docstring for the contract).

    Parameters
    ----------
    bounds : the search box, (m,) each.
    max_evals : the budget: points told in all (start and data told up front included), >= 1.
    name : used in messages.
    start : (m,) inside ``bounds``, or None. When given, it is asked first, before the method's
        own proposals, unless a success is already known or it was told (the user's known-safe
        start); None lets the method choose.
    start_retries : how many more times a start reported as failed is asked again while no trial
        has succeeded (default :data:`START_RETRIES`, once): on a robot a failed start is more often a
        wrong reading than a wrong start. A start that then succeeds was known safe all along: its
        failed readings no longer reach the safety model (:meth:`_safety_data`).
    confirm : trials that repeat the best at the end (default 0): when the method would stop, or
        when only this many trials are left in the budget, it asks its best again this many times
        (each time the best as it then stands), then stops for the reason it had. On a robot whose
        returns are noisy, a repeat tells a lucky reading from a good theta before it is deployed.

    Attributes
    ----------
    X_ : (d, m) every point told so far; ``success_`` (d,) bool; ``returns_`` (d,) float (NaN where
        no return was observed).
    """

    needs_success = False  # a safe method: stops with NO_SAFE_POINT while every trial failed
    answer_tolerance = ANSWER_TOLERANCE

    def __init__(self, bounds: Bounds, *, max_evals: int = 100, name: str = "optimizer", start=None,
                 start_retries: int = START_RETRIES, confirm: int = 0) -> None:
        if not isinstance(bounds, Bounds):
            raise InputError(f"bounds must be a corl.Bounds, got {type(bounds).__name__}")
        if isinstance(max_evals, bool) or int(max_evals) != max_evals or max_evals < 1:
            raise InputError(f"max_evals (the trial budget) must be an integer >= 1, got {max_evals!r}")
        self.bounds = bounds
        self.max_evals = int(max_evals)
        self.name = name
        self.start = None if start is None else as_point(start, bounds, name=name, what="start").copy()
        self._start_open = start is not None  # the start is still to be tried
        if isinstance(start_retries, bool) or not isinstance(start_retries, (int, np.integer)) or start_retries < 0:
            raise InputError(f"start_retries must be an integer >= 0 (how often a failed start is tried again), "
                             f"got {start_retries!r}")
        self.start_retries = int(start_retries)
        self._start_failures = 0  # failed readings of the start told so far
        self._whatif: int | None = None  # a failed trial read as a success by _safety_data (what-if decisions)
        if isinstance(confirm, bool) or not isinstance(confirm, (int, np.integer)) or confirm < 0:
            raise InputError(f"confirm must be an integer >= 0 (trials that repeat the best at the end), got {confirm!r}")
        self.confirm = int(confirm)
        self._confirmations = 0  # confirmation trials told
        self._confirm_reason: StopReason | None = None  # why the search stopped, once it confirms its best
        self._confirming = False  # the current proposal repeats the best
        m = bounds.dim
        self.X_ = np.empty((0, m))
        self.success_ = np.empty(0, dtype=bool)
        self.returns_ = np.empty(0)
        self._proposal: np.ndarray | None = None  # the next point, once decided
        self._handed_out = False  # True once ask() returned the proposal
        self._answered: np.ndarray | None = None  # the handed-out point told last, until the next ask()
        self._stop_reason: StopReason | None = None
        self._decided = False
        self._max_pending, self._out, self._told_out = 1, [], []  # K > 1: (point, confirming) out; told since ask


    def _set_max_pending(self, k: int) -> None:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise InputError(f"max_pending (trials out at once, one per robot) must be an integer >= 1, got {k!r}")
        if self._out or self._handed_out:
            raise StateError(f"{self.name}: set max_pending before the first ask, not while trials are pending")
        self._max_pending, self._decided = int(k), False

    max_pending = property(lambda self: self._max_pending, _set_max_pending,
                           doc="How many trials may be pending at once (K robots); 1 by default, set before the first ask")

    @property
    def pending_(self) -> np.ndarray:
        """(p, m) the points handed out by ask() and not told yet (max_pending > 1; else (0, m))."""
        return np.array([x for x, _ in self._out]).reshape(len(self._out), self.bounds.dim)

    @property
    def ready(self) -> bool:
        """A new trial can be asked now: not done, fewer than ``max_pending`` out and a point to propose."""
        self._decide()
        if self._max_pending == 1:
            return self._stop_reason is None and not self._handed_out
        return self._proposal is not None and len(self._out) < self._max_pending

    # -- the interface -------------------------------------------------------------------------
    def ask(self) -> np.ndarray:
        """Next point to evaluate, (m,); the same point until it is told. Raises :class:`StateError` when :attr:`done`.

        With ``max_pending > 1``, a new point each call while fewer than ``max_pending`` are out
        (:attr:`ready`); StateError when none can be handed out before a tell.
        """
        if self._max_pending > 1:
            return self._ask_another()
        self._decide()
        if self._stop_reason is not None:
            raise StateError(f"{self.name} has stopped ({self._stop_reason.value}): {_EXPLAIN[self._stop_reason]}. "
                             "Check .done before asking; read .best for the result")
        self._handed_out, self._answered = True, None
        return self._proposal.copy()

    def tell(self, x: np.ndarray, outcome=_MISSING) -> None:
        """Record the outcome (an :class:`Outcome` or ``(success, return)``) of evaluating ``x`` (m,).

        ``x`` need not have been asked. Bad input raises :class:`~corl.errors.InputError`, and a
        second answer to the point told last with no ``ask()`` since raises
        :class:`~corl.errors.StateError`; either records nothing.
        """
        _told(x, outcome)
        x = as_point(x, self.bounds, name=self.name)
        outcome = as_outcome(outcome)
        if self._max_pending > 1:
            return self._tell_any(x, outcome)
        asked = self._handed_out and self._proposal is not None and self._answers(x, self._proposal)
        if self._answered is not None and not asked and self._answers(x, self._answered):
            raise StateError(f"tell() without a pending ask(): {self.name} was told the outcome of "
                             f"{np.array2string(self._answered, precision=6)} already and nothing was asked "
                             "since; call ask() first (each asked point is told once)")
        self._record(x, outcome)
        if asked:
            self._answered = self._proposal  # told once: a second answer before the next ask() is refused
        answered = self._proposal is not None and self._answers(x, self._proposal)
        if answered and self._confirming:
            self._confirmations += 1
        if answered or not self._handed_out or self.n_evals >= self.max_evals:
            if self._proposal is not None and not answered:
                self._withdraw(self._proposal)  # decided from older data (or past the budget): decide again
            self._proposal, self._handed_out = None, False
        self._decided, self._stop_reason = self._proposal is not None, None
        self._observe(x, outcome)

    def _record(self, x: np.ndarray, outcome: Outcome) -> None:  # the told point joins the data (and the start's count)
        r = np.nan if outcome.return_ is None else float(outcome.return_)
        self.X_ = np.vstack([self.X_, x])
        self.success_ = np.append(self.success_, outcome.success)
        self.returns_ = np.append(self.returns_, r)
        if self.start is not None and self._answers(x, self.start) and not outcome.success:
            self._start_failures += 1
        if self._start_open and self._answers(x, self.start):
            # a failed start is asked again (start_retries) while nothing has succeeded yet
            retries = self.start_retries if self.needs_success else 0  # only a safe method refuses a failed start
            self._start_open = not outcome.success and self._start_failures <= retries

    # -- several trials out at once (max_pending > 1) ------------------------------------------
    def _ask_another(self) -> np.ndarray:
        self._decide()
        if self._stop_reason is not None:
            raise StateError(f"{self.name} has stopped ({self._stop_reason.value}): {_EXPLAIN[self._stop_reason]}. "
                             "Check .done before asking; read .best for the result")
        if self._proposal is None or len(self._out) >= self._max_pending:
            raise StateError(f"{self.name} has {len(self._out)} trials pending and no other to hand out before one "
                             "of them is told (check .ready before asking)")
        x = self._proposal
        self._out.append((x.copy(), self._confirming))
        self._proposal, self._decided, self._told_out = None, False, []  # the next one, given this one pending
        return x.copy()

    def _tell_any(self, x: np.ndarray, outcome: Outcome) -> None:
        hit = next((i for i, (p, _) in enumerate(self._out) if self._answers(x, p)), None)
        if hit is None and any(self._answers(x, p) for p in self._told_out):
            raise StateError(f"{self.name} was told the outcome of {np.array2string(x, precision=6)} already and "
                             "it is not pending again; each asked point is told once")
        self._record(x, outcome)
        if hit is not None:
            point, confirming = self._out.pop(hit)
            self._told_out.append(point)
            self._confirmations += int(confirming)
        if self._proposal is not None:  # decided from older data, not handed out: decide again
            self._withdraw(self._proposal)
        self._proposal, self._decided, self._stop_reason = None, False, None
        self._observe(x, outcome)

    def _spent(self) -> int:  # trials told plus trials pending: what the budget has committed
        return self.n_evals + len(self._out)

    @property
    def done(self) -> bool:
        """True once the budget is spent or the method's own stopping rule fired (see :attr:`stop_reason`)."""
        self._decide()
        return self._stop_reason is not None

    @property
    def stop_reason(self) -> StopReason | None:
        """Why the method stopped, or None while it runs; known before :meth:`ask`."""
        self._decide()
        return self._stop_reason

    @property
    def best(self) -> tuple[np.ndarray, float] | None:
        """The method's best: the successful point with the highest return and that return, or None.

        Methods with a return model whose noise is fitted (``CORL``) answer the *learner's best*
        instead, the sampled point with the highest posterior mean among those the model calls safe
        (:class:`corl.optimizers.safe.SafeBOOptimizer`); :attr:`best_observed` is the largest reading.
        """
        return self.best_observed

    @property
    def best_observed(self) -> tuple[np.ndarray, float] | None:
        """The successful point with the highest *reading* and that reading, or None (under noise, the luckiest)."""
        ok = self.success_ & np.isfinite(self.returns_)
        if not np.any(ok):
            return None
        idx = np.flatnonzero(ok)[np.argmax(self.returns_[ok])]
        return self.X_[idx].copy(), float(self.returns_[idx])

    @property
    def n_evals(self) -> int:
        return len(self.X_)

    # -- the decision, once per tell -----------------------------------------------------------
    def _decide(self) -> None:
        if self._decided:
            return
        left = self.confirm - self._confirmations  # confirmation trials still to run (``confirm``)
        self._confirming = False
        if self._spent() >= self.max_evals:
            decision = StopReason.BUDGET
        elif self._start_open and not np.any(self.success_):
            decision = self.start
        elif self.needs_success and self.n_evals and not np.any(self.success_):
            decision = StopReason.NO_SAFE_POINT  # checked before any model is fitted
        elif self._confirm_reason is not None and left <= 0:
            decision = self._confirm_reason  # confirmed: the stop the search had reached
        elif left > 0 and (self._confirm_reason is not None or self._spent() >= self.max_evals - left):
            self._confirm_reason = self._confirm_reason or StopReason.BUDGET  # the last trials confirm
            decision, self._confirming = self._best_theta(), True
        else:
            decision = self._propose()
            if left > 0 and isinstance(decision, StopReason) and np.any(self.success_):
                self._confirm_reason, decision, self._confirming = decision, self._best_theta(), True
        if decision is None:
            decision = StopReason.CONVERGED
        if self._out and (isinstance(decision, StopReason) or self._repeats_pending(decision)):
            self._stop_reason, self._proposal, self._decided = None, None, True  # no trial until a tell
            return
        if isinstance(decision, StopReason):
            self._stop_reason, self._proposal = decision, None
        else:
            x = np.asarray(decision, dtype=float).reshape(self.bounds.dim)
            self._stop_reason, self._proposal = None, self.bounds.clip(x)
        self._decided = True

    def _best_theta(self) -> np.ndarray:
        """The point a confirmation trial repeats: :attr:`best`'s (a subclass answers without deciding)."""
        return self.best_observed[0]

    def _safety_data(self) -> tuple[np.ndarray, np.ndarray]:
        """What the safety model g_S is fitted on: ``(X, success)``, (d', m) and (d',).

        Every trial, except the failed readings of a point that was tried again on purpose and then
        succeeded (:meth:`_rechecked`: the start, ``start_retries``, and points a subclass checks
        again): those failures were wrong readings. Left in, a failure and a success at one point put
        g_S's latent mean near 0 there, below any band: a run would stop at its start, or keep a hole
        in the safe set where one sensor reading was wrong.
        """
        success = self.success_
        if self._whatif is not None:  # a subclass asks what it would decide were this failed reading wrong
            success = success.copy()
            success[self._whatif] = True
        keep = np.ones(len(self.X_), dtype=bool)
        for x in self._rechecked():
            here = np.all(np.abs(self.X_ - x) <= self.answer_tolerance * self.bounds.width, axis=1)
            if np.any(here & success):
                keep &= ~(here & ~success)
        if keep.all():
            return self.X_, success
        return self.X_[keep], success[keep]

    def _repeats_pending(self, x) -> bool:  # x (m,) answers a pending point: the same motion as a trial out
        x = self.bounds.clip(np.asarray(x, dtype=float).reshape(self.bounds.dim))
        return any(self._answers(x, p) for p, _ in self._out)

    def _rechecked(self) -> list[np.ndarray]:
        """Points tried again on purpose after a failed reading (m,) each: the start, once it failed."""
        return [self.start] if self.start is not None and self._start_failures else []

    def _answers(self, x: np.ndarray, proposal: np.ndarray) -> bool:
        """``x`` answers ``proposal``: within ``answer_tolerance`` of the box width in every coordinate."""
        return bool(np.all(np.abs(x - proposal) <= self.answer_tolerance * self.bounds.width))

    # -- for subclasses ------------------------------------------------------------------------
    @abstractmethod
    def _propose(self) -> np.ndarray | StopReason | None:
        """Next point (m,), or the :class:`StopReason` to stop with (None means ``CONVERGED``)."""

    def _observe(self, x: np.ndarray, outcome: Outcome) -> None:
        """Hook called after each tell; the data is already in ``X_``, ``success_``, ``returns_``."""

    def _withdraw(self, x: np.ndarray) -> None:
        """Hook: the proposal ``x`` was decided but will not be evaluated (new data arrived first)."""
