"""Black-box methods over the full ``w`` with one reward, the baselines of Sec. VIII-A.

They ignore the structure of Eq. 5 and optimise the single objective

    o(w) = (J(w) - R(theta)) [S(theta) = 1] + failure_cost [S(theta) = 0]

(the paper uses ``failure_cost = 15``); the optimizer maximises ``-o(w)``. ``theta`` is only used for
reporting: ``theta = Theta(w)`` (``task.theta_of``).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from corl.errors import InputError, StateError
from corl.loop import drive
from corl.learner import Best, cost_of
from corl.numerics import as_vector
from corl.optimizers.base import BlackBoxOptimizer, StopReason
from corl.problem import Outcome, Proposal, Task

__all__ = ["DirectSearch"]


class DirectSearch:
    """Drive a :class:`BlackBoxOptimizer` over ``w`` with the single objective ``o(w)``.

    Trial 0 is the demonstration ``w0``; it is told to the optimizer like any other trial, so the
    optimizer's ``max_evals`` is the budget of the whole run, the demonstration included.
    The interface matches :class:`corl.CORL`: ``ask``, ``tell``, ``done``, ``stop_reason``,
    ``best``, ``run``; ``stop_reason`` is the optimizer's.
    """

    def __init__(self, task: Task, optimizer: BlackBoxOptimizer, *, failure_cost: float = 15.0) -> None:
        if task.w_bounds is None:
            raise InputError(f"task '{task.name}' has no w_bounds; methods over w need a box to search")
        self.task = task
        self.optimizer = optimizer
        self.failure_cost = float(failure_cost)
        self.history: list[tuple[Proposal, Outcome]] = []
        self.J_history: list[tuple[int, float]] = []
        self._pending: Proposal | None = None
        self._best: Best | None = None
        self._best_objective = -np.inf

    def ask(self) -> Proposal:
        if self._pending is not None:
            return self._pending
        if self.done:
            raise StateError(f"{self.optimizer.name} has finished; read .best")
        if not self.history:
            w = as_vector(self.task.demonstration().w, name="demonstration w")
            step = "demonstration"
        else:
            w, step = self.optimizer.ask(), "search"
        self._pending = Proposal(len(self.history), w, self.task.theta_of(w), step)
        return self._pending

    def tell(self, outcome: Outcome) -> None:
        if self._pending is None:
            raise StateError("tell() without a pending ask(): call ask() first, run its trial, then tell its outcome")
        if not isinstance(outcome, Outcome):
            raise InputError(f"tell() needs a corl.Outcome, got {type(outcome).__name__}")
        p, self._pending = self._pending, None
        J = cost_of(self.task, p.w)
        self.history.append((p, outcome))
        self.J_history.append((p.index, J))
        score = (float(outcome.return_) - J) if outcome.success else -self.failure_cost  # -o(w)
        self.optimizer.tell(p.w, Outcome(outcome.success, score if outcome.success else None, outcome.info))
        if outcome.success and score > self._best_objective:
            self._best_objective = score
            self._best = Best(p.w, p.theta, float(outcome.return_), J)

    @property
    def done(self) -> bool:
        return self._pending is None and bool(self.history) and self.optimizer.done

    @property
    def stop_reason(self) -> StopReason | None:
        """Why the search stopped (the optimizer's :class:`StopReason`), or None while it runs."""
        return self.optimizer.stop_reason if self.done else None

    @property
    def best(self) -> Best | None:
        return self._best

    def run(self, task: Task | None = None, *, max_trials: int | None = None,
            callback: Callable[[Proposal, Outcome], None] | None = None) -> Best | None:
        drive(self, task or self.task, max_trials=max_trials, callback=callback)
        return self.best
