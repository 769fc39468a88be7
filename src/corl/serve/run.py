"""The run a server holds: one learner bound to its store, answering ``ask`` and ``tell`` as JSON.

:class:`ServedRun` knows nothing of HTTP (:mod:`corl.serve.app` puts it on the network). It opens
the store for writing once, with the store's writer lock (:class:`corl.store.RunStore`), and holds
it until :meth:`close`: while a server runs, no other process writes that store.

Every change is committed before it is answered, and both calls are idempotent, so a client can
repeat any request after a lost response or a server restart:

* ``ask`` hands out the pending trial again while one is pending; otherwise it asks the learner,
  commits the proposal, then answers.
* ``tell`` of the pending trial commits the outcome, then tells the learner. A trial already told
  with the same outcome is answered again (``"repeated": true``); another outcome for it, or a trial
  that is not pending, is a :class:`Conflict` (HTTP 409).

With K robots (``corl serve --robots K``, :mod:`corl.serve.fleet`) each robot names itself in its asks and
gets its own pending trial again, and ``tell`` takes any pending trial by its index.

Reopened on the same store after a kill, the run replays its trials (:meth:`StoredRun.open`) and
goes on exactly where it stopped: nothing lost, nothing run twice.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from corl.errors import InputError, TaskError
from corl.problem import Outcome, Proposal
from corl.serve.fleet import Fleet, ask_robot, check_robot
from corl.serve.problems import Broken, Conflict, TaskCodeError, Timing
from corl.serve.problems import reason as _reason
from corl.store.records import TrialRecord

__all__ = ["ServedRun", "Conflict", "Broken", "TaskCodeError", "Timing", "CODE_KEYS"]

# Body keys that would name code or a run: the task is given on the server's command line only.
CODE_KEYS = ("task", "task_spec", "spec", "module", "factory", "method", "seed", "store", "path")
_ASK_KEYS = ("raw", "context", "robot")
_TELL_KEYS = ("trial", "success", "return", "info", "run")


class ServedRun:
    """The store's latest run (or a new one), its learner in memory, owned by one thread.

    SQLite and the learners are used from a single thread: :attr:`executor` (one worker) opens the
    store and runs every call that touches the learner or the store; :meth:`ask`, :meth:`tell` and
    :meth:`snapshot` must run there (``executor.submit``), which serializes them. :attr:`status` and
    :meth:`trials` read copies and may be read from any thread.

    For a task with contexts, an ask may name its scene (``{"context": [...]}``): the run of that scene
    is served from then on, found or started as :mod:`corl.serve.scenes` says; one trial is pending at
    a time, across scenes.

    Parameters
    ----------
    store_path : the run store; created when missing.
    task_spec : the task as the command line names it (``synthetic``, ``package.module:make_task``).
    method, seed : of a new run (defaults CORL+PIBU for a built-in task, CORL for your own; seed 0);
        with a run in the store, only that run's values are accepted.
    rate : Hz of the joint trajectories handed out (``task.reference(w, rate)``).
    robots : K of a new run, up to K trials out at once, one per robot (:mod:`corl.serve.fleet`); None: 1, or
        the stored run's K (another value is refused).
    """

    def __init__(self, store_path: str | Path, task_spec: str, *, method: str | None = None,
                 seed: int | None = None, rate: float = 100.0, robots: int | None = None) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self.executor = ThreadPoolExecutor(1, thread_name_prefix="corl-learner")
        try:
            self.executor.submit(self._open, store_path, task_spec, method, seed, rate, robots).result()
        except BaseException:
            self.executor.shutdown()
            raise

    def _open(self, store_path, task_spec: str, method, seed, rate, robots) -> None:
        from corl.methods import DEFAULT_METHOD, METHODS
        from corl.session import StoredRun, check_rate
        from corl.store import RunStatus, RunStore, StoreError, latest_run
        from corl.tasks.registry import BUILTIN_TASKS, load_task

        if method is not None and method not in METHODS:
            raise InputError(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
        self.rate = check_rate(rate)
        self.store_path = Path(store_path)
        self.task_spec = task_spec
        self.version = 0  # grows with every change a client can see
        self.broken: str | None = None
        self._asked: Proposal | None = None  # asked of the learner, not handed out yet
        self._method, self._parked = method, {}  # run id -> the state of a run the robot left (another scene)
        info = latest_run(self.store_path)  # read-only: a refused start leaves the store's bytes as they were
        if info is not None:
            for flag, given, stored in (("--method", method, info.method), ("--seed", seed, info.seed),
                                        ("--robots", robots, info.config.get("robots", 1))):
                if given is not None and given != stored:
                    raise InputError(f"{flag} {given} differs from run {info.id} in {self.store_path} ({stored}); "
                                     "drop the flag to serve that run, or give another --store")
            self.task = load_task(task_spec, seed=int(info.seed or 0))
            with RunStore(self.store_path, readonly=True) as db:
                session = StoredRun.open(db, self.task, info.id)
        else:
            seed = 0 if seed is None else seed
            self.task = load_task(task_spec, seed=seed)
            self.seed = seed
            if (robots or 1) > 1:  # SEIB keeps the K trials out apart (corl run --robots does the same)
                method = method or "CORL"
            method = method or ("CORL+PIBU" if task_spec in BUILTIN_TASKS else DEFAULT_METHOD)
            session = StoredRun.new(self.task, task_spec=task_spec, method=method, seed=seed, robots=robots or 1)
        self.db = RunStore(self.store_path)  # the writer lock, held until close()
        try:
            latest = self.db.latest_run()
            if (latest and latest.id) != (info and info.id):
                raise StoreError(f"another process started a run in {self.store_path} meanwhile; nothing was written: "
                                 "start corl serve again")
            session = session.attach(self.db)  # a run changed since it was read: StoreError
            if info is not None and info.status is not RunStatus.FINISHED and session.done:
                self.db.set_status(info.id, RunStatus.FINISHED)
            self._adopt(session)
        except BaseException:
            self.db.close()
            raise
        self.status = self._status()

    def _adopt(self, session) -> None:
        """Serve ``session`` (attached to the store) from now on: its trials, pending trial and scene."""
        from corl.serve.scenes import run_context

        self.session = session
        self.info = self.db.run(session.run_id)
        self.seed = int(self.info.seed or 0)
        c = run_context(self.info)
        own = getattr(self.task, "context", None)
        self.own_scene = c is None or own is None or np.array_equal(c, np.asarray(own, dtype=float))
        self.scene = self.task if self.own_scene else _scene(self.task, c)  # what reference() and the robot see
        self.robots = int(self.info.config.get("robots", 1))
        self.fleet = None if self.robots == 1 else Fleet(self.db, session.run_id, self.robots)
        pending = self.db.pending(session.run_id)
        self.pending: Proposal | None = None if pending is None else pending.proposal
        if self.fleet is not None:  # the oldest of the trials out, for what reads one
            self.pending = self.fleet.oldest
        self.records = self.db.trials(session.run_id)  # every trial, oldest first; outcome None while pending
        self._J = {i: _finite(J) for i, J in getattr(session.learner, "J_history", ()) or ()}
        self._best_told = None
        for r in self.records:
            self._note_best(r)

    def _to_scene(self, c) -> None:
        """Serve the run of scene ``c`` (:mod:`corl.serve.scenes`); refused while a trial is pending elsewhere."""
        from corl.serve.scenes import run_for_scene, same_scene

        if same_scene(self.info, c) and not self.session.done:
            return
        where = ", ".join(f"{v:g}" for v in c)
        if self.pending is not None:
            raise Conflict(f"trial {self.pending.index} of run {self.session.run_id} ({_where(self.info)}) is pending "
                           f"on the robot: tell its outcome (POST /tell) before asking in context [{where}]; one "
                           "trial is out at a time, across scenes")
        if self._method not in (None, "CORL"):
            raise InputError(f"this server was started with --method {self._method}; a run in a context learns "
                             "with CORL: restart corl serve without --method to learn in scenes")
        self._parked[self.session.run_id] = (self.session, self._J)
        self._asked = None
        session, created = run_for_scene(self.db, self.task, self.task_spec, c, method="CORL", seed=self.seed)
        parked = self._parked.pop(session.run_id, None)
        self._adopt(session if parked is None or created else parked[0])
        if parked is not None and not created:
            self._J = parked[1]
        self._changed()

    def close(self) -> None:
        """Release the store (and its writer lock), after the call in progress."""
        self.executor.submit(self.db.close).result()
        self.executor.shutdown()

    # -- ask -----------------------------------------------------------------------------------
    def ask(self, body: dict) -> tuple[dict, Timing]:
        """The next trial as JSON: the pending one while one is pending, else a new one, committed first."""
        raw = _check_keys(body, _ASK_KEYS, "ask").get("raw", False)
        if not isinstance(raw, bool):
            raise InputError(f"'raw' must be true or false, got {raw!r}")
        robot = check_robot(body.get("robot"))  # with one robot, a name changes nothing
        self._usable()
        if self.fleet is not None:
            if "context" in body:
                raise InputError(f"this server serves {self.robots} robots in one scene; an ask names no context "
                                 "with several robots (serve a run in a context with one robot)")
            return ask_robot(self, robot, raw)
        t0 = time.perf_counter()
        if "context" in body:
            from corl.serve.scenes import requested_context

            self._to_scene(requested_context(self.task, body["context"]))
        if not raw and getattr(self.task, "reference", None) is None:  # corl.problem.HasReference
            raise InputError(f"task '{self.task.name}' has no reference(w, rate), so corl cannot turn w into a "
                             "joint trajectory: ask with {\"raw\": true} (Client(url, raw=True)) for the raw "
                             "parameters w, which are NOT a joint trajectory (never send them to a robot), or "
                             "add reference() to the task")
        if self.pending is None and self.session.done:
            raise Conflict(f"run {self.session.run_id} has finished ({_reason(self.session)}): there is no next "
                           "trial; GET /status shows the result, and another --store starts a new run")
        proposal = self.pending
        if proposal is None:
            proposal = self._asked = self._asked or self.session.learner.ask()
        reference = None if raw else self._reference(proposal)
        t1 = time.perf_counter()
        commit = 0.0
        if self.pending is None:
            self.session.hand_out(proposal)  # committed before it is answered
            commit = self.session.commit_seconds
            self.pending, self._asked = proposal, None
            self.records.append(TrialRecord(proposal, None, "", None))
            self._changed()
        t2 = time.perf_counter()
        answer = {"trial": proposal.index, "run": self.session.run_id, "step": proposal.step,
                  "round": proposal.round, "theta": proposal.theta.tolist()}
        if self.info.config.get("context") is not None:  # the scene this trial is for
            answer["context"] = list(self.info.config["context"])
        if raw:
            answer["w"] = proposal.w.tolist()
            answer["raw"] = "the raw parameters w, NOT a joint trajectory: never send them to a robot"
        else:
            answer["reference"] = reference
        return answer, Timing(t1 - t0 + (t2 - t1 - commit), commit)

    def _reference(self, proposal: Proposal) -> dict:
        from corl.session import trajectory_of

        try:
            t, q = trajectory_of(self.scene, proposal.w, self.rate)
        except (Exception, SystemExit) as exc:  # the task's reference(), or its contract (NaN, shapes)
            handed = ("nothing was handed out" if self.fleet is None
                      else "the trial stays pending for the robot that asked")
            raise TaskCodeError(
                f"the task's reference(w, rate) failed on trial {proposal.index} ({type(exc).__name__}: {exc}); the "
                f"learner waits for this trial: fix the task and restart corl serve ({handed}), or ask "
                "with {\"raw\": true} and tell its outcome") from None
        names = getattr(self.task, "joint_names", None) or [f"q{j}" for j in range(q.shape[1])]
        return {"t": t.tolist(), "q": q.tolist(), "joint_names": list(names), "rate": self.rate}

    # -- tell ----------------------------------------------------------------------------------
    def tell(self, body: dict) -> tuple[dict, Timing]:
        """Commit the outcome of the pending trial, then tell the learner; a repeated tell is answered again."""
        _check_keys(body, _TELL_KEYS, "tell")
        for key in ("trial", "success"):
            if key not in body:
                raise InputError(f"tell needs '{key}': {{\"trial\": i, \"success\": true|false, \"return\": number|null}}")
        index = body["trial"]
        if isinstance(index, bool) or not isinstance(index, int) or index < 0:
            raise InputError(f"'trial' must be the index of the asked trial (an integer >= 0), got {index!r}")
        info = body.get("info", {})
        if not isinstance(info, dict):
            raise InputError(f"'info' must be a JSON object, got {type(info).__name__}")
        success, value = body["success"], body.get("return")
        if not isinstance(success, bool):
            raise InputError(f"'success' must be true or false, got {success!r}")
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise InputError(f"'return' must be a number or null, got {value!r}")
        if not success and value is not None:
            raise InputError("a failed trial is told without a return: send \"return\": null (or success true)")
        outcome = Outcome(success, value, info)  # a NaN, a missing return on success: InputError
        run = body.get("run", self.session.run_id)
        if isinstance(run, bool) or not isinstance(run, int):
            raise InputError(f"'run' must be the run id the trial came with (an integer), got {run!r}")
        self._usable()
        if run != self.session.run_id:  # a trial of a run the robot left: only a repeat of a told one is answered
            return self._told_elsewhere(run, index, outcome), Timing()
        t0 = time.perf_counter()
        if index < len(self.records) and self.records[index].outcome is not None:
            return self._repeated(index, outcome), Timing()
        if self.fleet is not None:
            if index not in self.fleet.out:
                now = (f"the pending ones are {self.fleet.describe()}" if self.fleet.out
                       else "no trial is pending: POST /ask first")
                raise Conflict(f"trial {index} is not pending, so it cannot be told: {now}")
        elif self.pending is None or index != self.pending.index:
            now = ("no trial is pending: POST /ask first" if self.pending is None
                   else f"the pending trial is {self.pending.index}")
            raise Conflict(f"trial {index} is not pending, so it cannot be told: {now}")
        try:
            if self.fleet is None:
                self.session.tell(outcome)  # committed, then the learner is told
            else:
                self.session.tell(outcome, index)
        except Exception as exc:
            if self._still_pending(index):
                raise  # refused before anything was written (a failed demonstration, ...)
            if isinstance(exc, TaskError):  # the task's code: a restart meets it again; the message says what helps
                self.broken = str(exc)
            else:
                self.broken = (f"the learner raised {type(exc).__name__} after trial {index} was stored ({exc}); "
                               "the store keeps every told trial: restart corl serve on the same store")
            self._told(index, outcome)
            raise Broken(self.broken) from exc
        self._told(index, outcome)
        t1 = time.perf_counter()
        status = self.status
        commit = self.session.commit_seconds  # the store; the rest is the learner's tell (its next step)
        return {"trial": index, "success": outcome.success, "return": outcome.return_, "done": status["done"],
                "stop_reason": status["stop_reason"], "trials": status["trials"], "failures": status["failures"]}, \
            Timing(t1 - t0 - commit, commit)

    def _told(self, index: int, outcome: Outcome) -> None:
        history = getattr(self.session.learner, "J_history", None) or [(None, None)]
        if history[-1][0] == index:
            self._J[index] = _finite(history[-1][1])
        proposal = self.pending if self.fleet is None else self.fleet.told(index)
        self.records[index] = TrialRecord(proposal, outcome, "", "")
        self._note_best(self.records[index])
        self.pending = None if self.fleet is None else self.fleet.oldest
        self._changed()

    def _still_pending(self, index: int) -> bool:
        if self.fleet is None:
            return self.db.pending(self.session.run_id) is not None
        return any(r.index == index for r in self.db.pending_trials(self.session.run_id))

    def _note_best(self, record: TrialRecord) -> None:
        """Keep ``_best_told``: the successful trial with the highest return (the first of equal ones)."""
        o = record.outcome
        if o is not None and o.success and (self._best_told is None or o.return_ > self._best_told["return"]):
            self._best_told = {"trial": record.index, "return": o.return_, "theta": record.proposal.theta.tolist()}

    def _told_elsewhere(self, run: int, index: int, outcome: Outcome) -> dict:
        """A tell of trial ``index`` of ``run``, not the run served now: answered again when that trial was told
        with this outcome (a repeat after a lost answer), else a :class:`Conflict`."""
        from corl.store import StoreError

        try:
            records = self.db.trials(run)
        except StoreError:
            records = []
        told = records[index].outcome if index < len(records) else None
        if told is None or told.success != outcome.success or told.return_ != outcome.return_:
            raise Conflict(f"trial {index} of run {run} is not pending, so it cannot be told: the server serves run "
                           f"{self.session.run_id} ({_where(self.info)}) now" + (
                               "" if self.pending is None else f", whose pending trial is {self.pending.index}"))
        status = self.status
        return {"trial": index, "run": run, "success": told.success, "return": told.return_, "done": status["done"],
                "stop_reason": status["stop_reason"], "trials": status["trials"], "failures": status["failures"],
                "repeated": True}

    def _repeated(self, index: int, outcome: Outcome) -> dict:
        stored = self.records[index].outcome
        same = (stored.success == outcome.success and stored.return_ == outcome.return_
                and dict(stored.info) == dict(outcome.info))
        if not same:
            told = "success" if stored.success else "failure"
            if stored.success == outcome.success and stored.return_ == outcome.return_:  # the info alone differs
                raise Conflict(f"trial {index} was already told ({told}, return {stored.return_}) with another info "
                               f"({json.dumps(dict(stored.info))[:200]}); a trial is told once, its info included: "
                               "nothing was changed (a repeat with that info is answered again)")
            raise Conflict(f"trial {index} was already told ({told}, return {stored.return_}); a trial is told once, "
                           "and this tell says otherwise: nothing was changed")
        status = self.status
        return {"trial": index, "success": stored.success, "return": stored.return_, "done": status["done"],
                "stop_reason": status["stop_reason"], "trials": status["trials"], "failures": status["failures"],
                "repeated": True}

    # -- reading -------------------------------------------------------------------------------
    def snapshot(self):
        """``(version, records, J (d,), return map data or the reason there is none, theta labels)``,
        copies the dashboard draws from (run it in :attr:`executor`)."""
        from corl.experiments.figures import return_map_data

        J = np.array([np.nan if self._J.get(r.index) is None else self._J[r.index] for r in self.records], dtype=float)
        try:
            data = return_map_data(self.session.learner)
        except ValueError:
            data = ("No return map yet: it appears with the first black-box step over theta (a method over w "
                    "has none).")
        labels = tuple(getattr(self.task, "theta_labels", ()) or ("theta 1", "theta 2"))
        return self.version, list(self.records), J, data, labels

    def last_told(self) -> tuple | None:
        """``(index, w of the demonstration, w of the last told trial)``, or None before the first tell."""
        told = [r for r in self.records if r.outcome is not None]
        if not told or not self.own_scene:  # the video renders the task's own scene only
            return None
        return told[-1].index, self.records[0].proposal.w, told[-1].proposal.w

    def trials(self, since: int = 0) -> list[dict]:
        """The trials from index ``since`` on, oldest first (a pending one has ``success`` null)."""
        return [_row(r.proposal, r.outcome, self._J.get(r.index)) for r in self.records[max(0, since):]]

    def _usable(self) -> None:
        if self.broken:
            raise Broken(self.broken)

    def _changed(self) -> None:
        self.version += 1
        self.status = self._status()

    def _status(self) -> dict:
        """What GET /status answers: counts, the pending trial, the learner's best and the best observed reading,
        done and why."""
        from corl.serve.scenes import runs_summary
        from corl.session import best_record

        s = self.session
        told = [r.outcome for r in self.records if r.outcome is not None]
        best = s.best
        reason = getattr(s.learner, "stop_reason", None)
        return {
            "run": s.run_id, "task": self.task.name, "task_spec": self.task_spec, "method": self.info.method,
            "seed": self.info.seed, "store": str(self.store_path), "trials": len(told),
            "failures": sum(not o.success for o in told),
            "pending": None if self.pending is None else self.pending.index,
            "step": self.records[-1].proposal.step if self.records else None,
            "round": self.records[-1].proposal.round if self.records else None,
            "best": None if best is None else {**best_record(s.learner), "J": _finite(getattr(best, "J", None))},
            "best_observed": self._best_told,  # the highest reading told: under noise the luckiest, not deployed
            "done": bool(s.done), "stop_reason": None if reason is None else getattr(reason, "value", str(reason)),
            "theta_dim": self.task.theta_bounds.dim, "version": self.version, "broken": self.broken,
            "context": self.info.config.get("context"),  # the scene of the run served now (None: no contexts)
            "runs": runs_summary(self.db),  # every run of the store, each with its scene
            **({} if self.fleet is None else self.fleet.status()),  # K > 1 robots: the trials out, who holds them
        }


def _scene(task, c):
    from corl.contexts.skill import scene_of

    return scene_of(task, c)


def _where(info) -> str:
    c = info.config.get("context")
    return "no context" if c is None else "context [" + ", ".join(f"{float(v):g}" for v in c) + "]"


def _check_keys(body, allowed: tuple[str, ...], what: str) -> dict:
    if not isinstance(body, dict):
        raise InputError(f"the body of {what} must be a JSON object, got {type(body).__name__}")
    code = [k for k in body if k in CODE_KEYS]
    if code:
        raise InputError(f"a request cannot name '{code[0]}': the task, method, seed and store are given on the "
                         "server's command line only (corl serve --task ...), never by a client")
    unknown = [k for k in body if k not in allowed]
    if unknown:
        raise InputError(f"unknown field '{unknown[0]:.40}' in {what}; it takes {', '.join(allowed)}")
    return body


def _row(p: Proposal, o: Outcome | None, J: float | None) -> dict:
    return {"trial": p.index, "step": p.step, "round": p.round, "theta": np.asarray(p.theta).tolist(),
            "success": None if o is None else o.success, "return": None if o is None else o.return_, "J": J}


def _finite(x) -> float | None:
    return float(x) if x is not None and math.isfinite(float(x)) else None

