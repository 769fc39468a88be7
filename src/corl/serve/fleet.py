"""``corl serve --robots K``: up to K trials out at once, one per robot (:class:`corl.parallel.ParallelCORL`).

A robot names itself in every ask (``{"robot": "arm-1"}``: 1-64 letters, digits, ``_``, ``.``, ``-``):

* a robot whose trial is pending gets that trial again (an idempotent re-ask, as with one robot);
* a robot without one gets a pending trial no robot holds (a server killed between committing a trial and
  committing its robot, or a run started by ``corl run --robots K``), else a new trial of the learner
  (:meth:`corl.session.StoredRun.try_ask`), committed before it is answered;
* when nothing can go out before a tell (K trials are out, or Algorithm 1 needs an outcome before its next
  trial) the answer is HTTP 503 with ``Retry-After: 1`` (:class:`Busy`): ask again after a tell. Once
  Algorithm 1 has stopped with trials still out, a robot without a trial gets 409: nothing more comes.

An ask without ``robot`` is refused (400): with K robots the server could not hand a lost answer's trial
back to the robot that asked. Which robot holds which trial is kept in the store
(:meth:`corl.store.RunStore.set_holder`), so a restarted server hands each robot its pending trial again.
Any robot (or anyone) may tell the outcome of any pending trial, by its index, in any order.
"""

from __future__ import annotations

import re

import time

from corl.errors import CorlError, InputError
from corl.problem import Proposal
from corl.serve.problems import Conflict, Timing, reason
from corl.store.records import TrialRecord

__all__ = ["Busy", "Fleet", "ask_robot", "check_robot", "ROBOT_PATTERN"]

ROBOT_PATTERN = re.compile(r"[A-Za-z0-9_.-]{1,64}")


class Busy(CorlError):
    """Nothing can go out before a tell (HTTP 503, ``Retry-After``): ask again once a trial is told."""

    retry_after = 1


def check_robot(value) -> str | None:
    """``value`` as a robot's name (1-64 of ``[A-Za-z0-9_.-]``), None when not given, or one InputError."""
    if value is None:
        return None
    if not isinstance(value, str) or not ROBOT_PATTERN.fullmatch(value):
        raise InputError(f"'robot' must be a name of 1 to 64 letters, digits, '_', '.' or '-', got {value!r:.80}")
    return value


class Fleet:
    """The trials out on the robots of one served run: trial index -> proposal, and -> the robot holding it."""

    def __init__(self, db, run_id: int, robots: int) -> None:
        self.robots = robots
        self.out: dict[int, Proposal] = {r.proposal.index: r.proposal for r in db.pending_trials(run_id)}
        held = db.holders(run_id)
        self.holder: dict[int, str | None] = {i: held.get(i) for i in self.out}

    @property
    def oldest(self) -> Proposal | None:
        return self.out[min(self.out)] if self.out else None

    def of(self, robot: str) -> Proposal | None:
        """The pending trial ``robot`` holds, or None."""
        return next((self.out[i] for i in sorted(self.out) if self.holder.get(i) == robot), None)

    def unheld(self) -> Proposal | None:
        """The oldest pending trial no robot holds, or None."""
        return next((self.out[i] for i in sorted(self.out) if self.holder.get(i) is None), None)

    def hold(self, proposal: Proposal, robot: str) -> None:
        self.out[proposal.index] = proposal
        self.holder[proposal.index] = robot

    def told(self, index: int) -> Proposal:
        self.holder.pop(index, None)
        return self.out.pop(index)

    def describe(self) -> str:
        """``trials 4 (robot a), 5 (robot b)``."""
        parts = [f"{i}" + ("" if self.holder.get(i) is None else f" (robot {self.holder[i]})") for i in sorted(self.out)]
        return ("trial " if len(parts) == 1 else "trials ") + ", ".join(parts)

    def busy(self) -> Busy:
        """What a robot without a trial is answered while nothing can go out before a tell."""
        n = len(self.out)
        if n >= self.robots:
            return Busy(f"{n} trials are out ({self.describe()}), one per robot of {self.robots}; ask again after "
                        "a tell")
        return Busy(f"no trial can go out before a tell: Algorithm 1 waits for the outcome of {self.describe()} "
                    f"(it hands out up to {self.robots} at once only where its steps allow); ask again after a tell")

    def status(self) -> dict:
        """What GET /status adds with K > 1 robots."""
        return {"pending_trials": sorted(self.out), "pending_robots": [self.holder.get(i) for i in sorted(self.out)],
                "robots": self.robots}


def ask_robot(served, robot: str | None, raw: bool) -> tuple[dict, Timing]:
    """An ask of ``served`` (a :class:`corl.serve.run.ServedRun`, in its executor) with K > 1 robots (module
    docstring): the robot's pending trial, one no robot holds, or a new one, committed with the robot's name
    before it is answered; :class:`Busy` while none can go out."""
    fleet, run = served.fleet, served.session.run_id
    if robot is None:
        raise InputError(f"this server serves {fleet.robots} robots: name yours in every ask, "
                         "{\"robot\": \"arm-1\"} (Client(url, robot=\"arm-1\")), so that a repeated ask gets "
                         "its trial back")
    t0 = time.perf_counter()
    proposal, commit = fleet.of(robot), 0.0
    if proposal is None:
        _refuse_finished(served)
        proposal = fleet.unheld()
        if proposal is None:
            proposal = served.session.try_ask()  # committed before it is answered (a wait is noted)
            if proposal is None:
                if getattr(served.session.learner, "stop_reason", None) is not None:
                    served._changed()  # Algorithm 1 ended as it was asked (once: the next asks stop above)
                _refuse_finished(served)
                raise fleet.busy()
            commit = served.session.commit_seconds
            served.records.append(TrialRecord(proposal, None, "", None))
            fleet.hold(proposal, None)  # out, held by no robot until its name is committed (as after a restart)
        t1 = time.perf_counter()
        served.db.set_holder(run, proposal.index, robot)  # which robot has it: a restart hands it back
        commit += time.perf_counter() - t1
        fleet.hold(proposal, robot)
        served.pending = fleet.oldest
        served._changed()
    reference = None if raw else served._reference(proposal)
    answer = {"trial": proposal.index, "run": run, "step": proposal.step, "round": proposal.round,
              "theta": proposal.theta.tolist(), "robot": robot}
    if raw:
        answer["w"] = proposal.w.tolist()
        answer["raw"] = "the raw parameters w, NOT a joint trajectory: never send them to a robot"
    else:
        answer["reference"] = reference
    return answer, Timing(time.perf_counter() - t0 - commit, commit)


def _refuse_finished(served) -> None:
    """Conflict once the run hands out no more trials: finished, or stopped with trials still out."""
    session, run = served.session, served.session.run_id
    if session.done:
        raise Conflict(f"run {run} has finished ({reason(session)}): there is no next trial; GET /status shows the "
                       "result, and another --store starts a new run")
    if getattr(session.learner, "stop_reason", None) is not None and served.fleet.out:
        raise Conflict(f"run {run} has stopped ({reason(session)}) and hands out no more trials; it waits for the "
                       f"outcome of {served.fleet.describe()}")
