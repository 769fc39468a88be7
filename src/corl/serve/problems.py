"""What the calls of a served run (:class:`corl.serve.run.ServedRun`) raise, and the time they report."""

from __future__ import annotations

from dataclasses import dataclass

from corl.errors import CorlError, StateError

__all__ = ["Conflict", "TaskCodeError", "Broken", "Timing", "reason"]


class Conflict(StateError):
    """A request that does not fit the run's state (HTTP 409): a tell of a trial that is not pending."""


class TaskCodeError(CorlError):
    """The task's own code failed on a trial (its ``reference()``): not the request's fault (HTTP 500)."""


class Broken(CorlError):
    """The learner raised after a commit: the server answers nothing more until it is restarted."""


@dataclass(frozen=True)
class Timing:
    """Seconds one call spent computing (the learner, the reference) and committing to the store."""

    compute: float = 0.0
    commit: float = 0.0


def reason(session) -> str:
    """Why the run of ``session`` (a :class:`corl.session.StoredRun`) stopped, in words."""
    if session.ended is not None:  # corl run --resume --end-at-error
        e = session.ended
        return f"ended at trial {e['trial']}, where the task's {e['member']} raised {e['error']}"
    why = getattr(session.learner, "stop_reason", None)
    return f"stop reason {getattr(why, 'value', why)}"
