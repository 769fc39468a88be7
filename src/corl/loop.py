"""The loops around the ask/tell interface: :func:`drive` (a learner on a task) and
:func:`optimize` (a black-box method on a function of theta, for users without a trajectory)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from corl import checks
from corl.errors import InputError, RolloutError
from corl.optimizers.base import BlackBoxOptimizer, StopReason, as_outcome
from corl.problem import Outcome, Proposal, Task

__all__ = ["drive", "optimize", "OptimizeResult"]


def drive(learner, task: Task, *, max_trials: int | None = None,
          callback: Callable[[Proposal, Outcome], None] | None = None, pending_hint: str = "",
          rollout: Callable[[np.ndarray], Outcome] | None = None) -> int:
    """Run ``learner`` (anything with ask/tell/done) on ``task.rollout`` (or ``rollout``, e.g. a worker
    process's, :mod:`corl.tasks.worker`) until done.

    A rollout that raises or returns something other than an :class:`Outcome` raises
    :class:`RolloutError`; its trial stays pending, so calling ``drive`` again retries it.
    Returns the number of trials told.
    """
    checks.function("callback", callback, what="(proposal, outcome) -> None")
    rollout = task.rollout if rollout is None else rollout
    count = 0
    while not learner.done and (max_trials is None or count < max_trials):
        proposal = learner.ask()  # the stopping contract: done is known before ask, which never signals a stop
        try:
            outcome = rollout(proposal.w)
        except Exception as exc:
            raise RolloutError(
                f"the rollout of trial {proposal.index} ({proposal.step}) raised {type(exc).__name__}: {exc}. "
                f"The trial stays pending{pending_hint}: fix the task and run again, or tell() its outcome"
            ) from exc
        if not isinstance(outcome, Outcome):
            raise RolloutError(f"task.rollout must return a corl.Outcome, got {type(outcome).__name__}; "
                               f"trial {proposal.index} stays pending")
        learner.tell(outcome)
        count += 1
        if callback is not None:
            callback(proposal, outcome)
    return count


@dataclass(frozen=True)
class OptimizeResult:
    """What :func:`optimize` returns.

    Attributes
    ----------
    theta : (m,) the successful point with the highest return, or None when nothing succeeded.
    return_ : its return, or None.
    stop_reason : why the optimizer stopped (:class:`corl.optimizers.base.StopReason`).
    trials : evaluations of ``f``, the start included; failures : how many of them failed.
    optimizer : the optimizer itself (``X_``, ``success_``, ``returns_``: every trial), ready to
        take more trials after a stop that new data can lift.
    """

    theta: np.ndarray | None
    return_: float | None
    stop_reason: StopReason
    trials: int
    failures: int
    optimizer: BlackBoxOptimizer


def optimize(f: Callable[[np.ndarray], object], bounds, start, *, method: str = "CORL", budget: int = 50,
             seed=None, settings=None, callback: Callable[[np.ndarray, Outcome], None] | None = None) -> OptimizeResult:
    """Maximise a black-box ``f`` over a box with one of corl's methods, from ``start``.

    ``f(theta)`` (theta (m,)) returns an :class:`Outcome` or a tuple ``(success, return)``
    (``return`` may be None on a failure). ``start`` is the first trial; ``budget`` counts every
    trial, the start included. The rest is :func:`corl.optimizers.registry.make_optimizer`'s.

    Raises
    ------
    InputError : bad arguments (see ``make_optimizer``), a start that fails under a safe method
        (CORL, PIBU, SAL grow the safe set from it), or a bad value from ``f`` (a NaN return, a success
        without a return, ...).
    RolloutError : ``f`` raised.

    Notes
    -----
    In both cases the error's ``optimizer`` attribute holds the optimizer, every trial so far told
    and the failed one still pending: nothing is lost.
    """
    from corl.optimizers.registry import make_optimizer

    checks.function("f", f, what="f(theta) -> Outcome or (success, return)", optional=False)
    checks.function("callback", callback, what="(theta, outcome) -> None")
    opt = make_optimizer(method, bounds, start, budget=budget, seed=seed, settings=settings)
    while not opt.done:
        x = opt.ask()
        where = f"trial {opt.n_evals + 1} at theta {np.array2string(x, precision=6)}"
        try:
            value = f(x.copy())
        except Exception as exc:
            raise _keeping(RolloutError(f"f raised {type(exc).__name__} in {where}: {exc}; the trial stays pending "
                                        "in error.optimizer"), opt) from exc
        try:
            outcome = as_outcome(value)
        except InputError as exc:
            raise _keeping(InputError(f"f returned a bad value in {where}: {exc}"), opt) from None
        opt.tell(x, outcome)
        if callback is not None:
            callback(x, outcome)
    if opt.stop_reason is StopReason.NO_SAFE_POINT and 0 < opt.n_evals == getattr(opt, "_start_failures", 1):
        times = "once" if opt.n_evals == 1 else f"all {opt.n_evals} times it was tried (start_retries={opt.n_evals - 1})"
        raise _keeping(InputError(
            f"the start {np.array2string(opt.X_[0], precision=6)} failed {times}: {opt.name} grows the safe set "
            "from a successful start; give a start known to succeed"), opt)
    best = opt.best
    return OptimizeResult(theta=None if best is None else best[0], return_=None if best is None else best[1],
                          stop_reason=opt.stop_reason, trials=opt.n_evals, failures=int(np.sum(~opt.success_)),
                          optimizer=opt)


def _keeping(error: Exception, optimizer) -> Exception:
    error.optimizer = optimizer
    return error
