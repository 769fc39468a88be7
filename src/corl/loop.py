"""The one learning loop every ask/tell learner shares: ask, roll out, tell."""

from __future__ import annotations

from typing import Callable

from corl.errors import RolloutError, StateError
from corl.problem import Outcome, Proposal, Task

__all__ = ["drive"]


def drive(learner, task: Task, *, max_trials: int | None = None,
          callback: Callable[[Proposal, Outcome], None] | None = None, pending_hint: str = "") -> int:
    """Run ``learner`` (anything with ask/tell/done) on ``task.rollout`` until done.

    A rollout that raises or returns something other than an :class:`Outcome` raises
    :class:`RolloutError`; its trial stays pending, so calling ``drive`` again retries it.
    Returns the number of trials told.
    """
    count = 0
    while not learner.done and (max_trials is None or count < max_trials):
        try:
            proposal = learner.ask()
        except StateError:
            break
        try:
            outcome = task.rollout(proposal.w)
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
