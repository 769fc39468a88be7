"""A learner bound to a run store: nothing is handed out or accepted before it is on disk.

:class:`StoredRun` wraps any ask/tell learner (CORL or a baseline):

* ``ask`` commits the proposal before returning it;
* ``tell`` commits the outcome before the learner sees it;
* :meth:`StoredRun.open` rebuilds the learner from the run's configuration and replays every
  stored trial (:func:`corl.store.replay`), so a run killed at any moment continues exactly where
  it stopped: same trials, same result, nothing lost or repeated. A trial that was handed out but
  never answered is handed out again.

The task itself is never read from the store: it is named on the command line (a built-in name or
an import path) and checked against the name recorded with the run.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np

from corl import checks
from corl.errors import CorlError, DemonstrationFailedError, InputError, StateError, TaskError
from corl.loop import drive
from corl.problem import Outcome, Proposal, Task, task_error
from corl.store import RunStatus, RunStore, StoreError, replay
from corl.store.resume import way_on

__all__ = ["StoredRun", "trajectory_of", "check_rate", "check_context", "MAX_RATE_HZ"]


def _build(task: Task, method: str, seed: int, corl_overrides: dict | None = None, robots: int = 1):
    """The learner; ``corl_overrides`` replace fields of the task's CORLConfig (``--rollout-every-step``);
    ``robots`` K > 1: Algorithm 1 with up to K trials out (:class:`corl.parallel.ParallelCORL`)."""
    from corl.learner import CORL
    from corl.methods import make_method
    from corl.parallel import ParallelCORL

    learner = make_method(method, task, seed=seed, **({"settings": _settings(task, corl_overrides)}
                                                       if corl_overrides else {}))
    if robots == 1:
        return learner
    if not isinstance(learner, CORL):
        raise InputError(f"several robots (--robots {robots}) share Algorithm 1's black-box step, and method "
                         f"'{method}' searches w without it; choose CORL (or CORL+PIBU, ...), or one robot")
    return ParallelCORL(learner.task, learner.optimizer_factory, learner.config, seed=seed, robots=robots)


def _settings(task: Task, corl_overrides: dict | None):
    from dataclasses import replace

    from corl.methods import settings_for

    settings = settings_for(task)  # the same defaults as without overrides (a user's task: fitted GPs)
    return replace(settings, corl=replace(settings.corl, **corl_overrides)) if corl_overrides else settings


def _build_in_context(task: Task, method: str, seed: int, corl_overrides: dict | None, context, store,
                      upto: dict, skill: dict | None = None):
    """The learner of a run in ``context``: what the store's runs named by ``upto`` (run id -> told
    trials, :func:`corl.contexts.snapshot`) taught (:mod:`corl.contexts`); ``skill``: settings of its
    :class:`corl.contexts.Skill` (``{"p_min": 0.9}``), the defaults when None."""
    from corl.contexts import ContextualCORL, Skill, context_task, failed_motions, learned, plain_learner
    from corl.contexts.skill import scene_of

    task = context_task(task)
    if method != "CORL":
        raise InputError(f"a run in a context learns with the CORL method (SEIB on GPs over (theta, c)); "
                         f"got --method {method}: drop it, or drop --context")
    c = np.asarray(context, dtype=float)
    scene = scene_of(task, c) if not np.array_equal(c, np.asarray(task.context, dtype=float)) else task
    settings = _settings(scene, corl_overrides)
    data, anchors = learned(store, task, upto=upto) if store is not None and upto else (None, [])
    if not anchors:  # the first context: Algorithm 1 from the demonstration of that scene
        return plain_learner(scene, seed=seed, settings=settings)
    return ContextualCORL(task, c, Skill(task, data, anchors, **(skill or {})), settings=settings, seed=seed,
                          failed=failed_motions(store, task, c, upto=upto))


def check_context(task: Task, context) -> np.ndarray:
    """``context`` as a point of the task's context box, or one InputError (a task without contexts too)."""
    from corl.contexts import context_task
    from corl.problem import check_theta

    task = context_task(task)
    try:
        return check_theta(context, task.context_bounds, task=task.name, what="context")
    except (TypeError, ValueError):
        raise InputError(f"--context needs {task.context_bounds.dim} numbers, got {context!r:.60}") from None


class StoredRun:
    """An ask/tell learner whose trials are committed to ``store`` under ``run_id``.

    A command that may still be refused builds the run first and writes nothing: a new run with
    :meth:`new`, an existing one with :meth:`open` on a read-only store. Only once the command is
    accepted does it open the store for writing and :meth:`attach` the run to it, so a refused
    command leaves the store file untouched, its bytes and its modification time.
    """

    def __init__(self, learner, store: RunStore | None, run_id: int | None) -> None:
        self.learner = learner
        self.store = store
        self.run_id = run_id
        self._record: dict | None = None  # what create_run stores, for a run not in a store yet
        self._seen: tuple | None = None  # the stored run as it was read: trials, outcomes, status
        self.ended: dict | None = None  # where the run was ended at a task error (RunStore.set_end), or None
        self.commit_seconds = 0.0  # what the last ask or tell spent committing to the store

    # -- creating and reopening ----------------------------------------------------------------
    @classmethod
    def new(cls, task: Task, *, task_spec: str, method: str, seed: int,
            corl_overrides: dict | None = None, context=None, learned_from: RunStore | None = None,
            skill: dict | None = None, robots: int = 1, upto: dict | None = None) -> "StoredRun":
        """A new run of ``method`` on ``task``, in no store yet (:meth:`attach` creates it there).

        ``task_spec`` is how the command line named the task; ``corl_overrides`` (e.g.
        ``{"rollout_every_step": False}``) replace fields of the task's CORLConfig, are stored with
        the run and applied again when it is reopened. A method that cannot run the task raises here.
        ``context`` (k,): learn in that scene from what the runs of ``learned_from`` (the store it
        will be attached to, read-only) taught (:mod:`corl.contexts`); the run records its context.
        ``skill``: settings of the skill it starts from (``{"p_min": 0.9}``, :class:`corl.contexts.Skill`),
        stored with the run (``config["skill"]``) and applied again when it is reopened. ``robots`` K > 1:
        up to K trials out at once (``config["robots"]``; :meth:`try_ask`, ``tell(outcome, index)``).
        ``upto`` (run id -> told trials, :func:`corl.contexts.snapshot`'s form): learn from only these of
        ``learned_from``'s runs and trials (``corl bench contexts --robots K``: the waves before); default all.
        A :class:`corl.tasks.noisy.NoisyTask` records its sensors (``config["noise"]``); reopening the
        run takes the task as given, so wrap it in the same sensors again (``corl run --resume`` does).
        """
        from corl.problem import context_of
        from corl.tasks.noisy import NoisyTask

        given, upto = upto, {}
        robots = checks.integer("robots", robots, low=1)
        if robots > 1 and context is not None:
            raise InputError("several robots (--robots) learn one scene; a run in a context (--context) has one robot "
                             "for now: drop one of them")
        if context is not None:
            from corl.contexts import context_task, snapshot

            context = check_context(task, context)
            seen = snapshot(learned_from, context_task(task)) if learned_from is not None else {}
            upto = seen if given is None else {str(key): int(n) for key, n in given.items()}
            if any(seen.get(key, -1) < n for key, n in upto.items()):
                raise InputError(f"upto {upto} names runs or trials that {getattr(learned_from, 'path', None)} "
                                 f"does not hold ({seen}); take it from the store learned from")
            learner = _build_in_context(task, method, seed, corl_overrides, context, learned_from, upto, skill)
        elif skill:
            raise InputError("skill settings (--p-min) apply to a run in a context: add --context, or drop them")
        else:
            learner = _build(task, method, seed, corl_overrides, robots)
        config = {"task_spec": task_spec, "task_name": task.name}
        if robots > 1:
            config["robots"] = robots
        if corl_overrides:
            config["corl_overrides"] = dict(corl_overrides)
        if isinstance(task, NoisyTask):  # the sensors the trials are read through (corl run --return-noise)
            config["noise"] = task.noise.as_dict()
        own = context_of(task)
        if context is not None or own is not None:  # a task with contexts: every run records its scene
            config["context"] = _plain(context if context is not None else own)
            config["contextual"] = context is not None
            if context is not None:
                config["learned_from"] = upto  # exactly what it learned from: reopened, it reads the same
                if skill:
                    config["skill"] = dict(skill)
        cfg = getattr(learner, "config", None)
        if cfg is not None:
            config["learner"] = _plain(asdict(cfg))
        run = cls(learner, None, None)
        run._record = {"task": task.name, "method": method, "seed": seed, "config": config}
        return run

    @classmethod
    def start(cls, store: RunStore, task: Task, *, task_spec: str, method: str, seed: int,
              corl_overrides: dict | None = None) -> "StoredRun":
        """A new run created in ``store`` now (:meth:`new`, then :meth:`attach`)."""
        return cls.new(task, task_spec=task_spec, method=method, seed=seed, corl_overrides=corl_overrides).attach(store)

    @classmethod
    def open(cls, store: RunStore, task: Task, run_id: int | None = None, *, end_at_error: bool = False) -> "StoredRun":
        """Reopen a run (default: the latest one) and replay its trials into a fresh learner.

        ``store`` may be read-only: the replay only reads; :meth:`attach` a writer to go on. The task's
        code raising in the replay is a :class:`TaskError`; with ``end_at_error``, one on the follow-up of
        the run's last told trial (where the run stopped when it ran) ends the run there instead:
        :attr:`ended` says where and why, and :meth:`attach` records it (``corl run --resume --end-at-error``).
        """
        info = store.run(run_id) if run_id is not None else store.latest_run()
        if info is None:
            raise StoreError(f"{store.path} holds no run yet; start one with 'corl run' or 'corl ask --task ...'")
        if info.task != task.name:
            raise InputError(f"run {info.id} in {store.path} is for task '{info.task}', but the task given is "
                             f"'{task.name}'; name the same task as when the run was started")
        seed = 0 if info.seed is None else int(info.seed)
        if info.config.get("contextual"):  # learned in a context: from what it learned from when it started
            upto = info.config.get("learned_from")
            if upto is None:  # a run of corl before learned_from was recorded: the runs before it, whole
                upto = {str(r.id): r.n_told for r in store.runs() if r.id < info.id}
            learner = _build_in_context(task, info.method, seed, info.config.get("corl_overrides"),
                                        check_context(task, info.config["context"]), store, upto,
                                        info.config.get("skill"))
        else:
            learner = _build(task, info.method, seed, info.config.get("corl_overrides"), info.config.get("robots", 1))
        ended = store.end(info.id)
        try:
            replay(learner, store, info.id)
        except TaskError as exc:
            if not (end_at_error and exc.trial == info.n_told - 1 == info.n_trials - 1):
                raise
            ended = {"trial": exc.trial, "member": exc.member, "error": exc.detail}
        run = cls(learner, store, info.id)
        run._seen, run.ended = _snapshot(info), ended
        return run

    def attach(self, store: RunStore) -> "StoredRun":
        """Commit to ``store`` from now on: create the run there when it is new; a reopened run must be
        as it was read (:meth:`open`), else another process wrote it meanwhile and StoreError says so."""
        if self.run_id is None:
            self.run_id = store.create_run(**self._record)
        elif _snapshot(store.run(self.run_id)) != self._seen:
            raise StoreError(f"run {self.run_id} in {store.path} changed while this command read it (another "
                             "process wrote to it); nothing was written: run the command again")
        if self.ended is not None and store.end(self.run_id) is None:
            store.set_end(self.run_id, self.ended)
        self.store = store
        return self

    # -- ask / tell ----------------------------------------------------------------------------
    def ask(self) -> Proposal:
        return self.hand_out(self.learner.ask())

    def try_ask(self) -> Proposal | None:
        """The next trial, committed and handed out, or None while none can go out before a tell (several
        robots: :meth:`corl.parallel.ParallelCORL.try_ask`; that it had none is noted too, :mod:`corl.store.meta`)."""
        try_ask = getattr(self.learner, "try_ask", None)
        if try_ask is None:
            return None if self.learner.done else self.ask()
        proposal = try_ask()
        if proposal is None:
            self.store.note_wait(self.run_id)
            if self.learner.done:  # Algorithm 1 ended as it was asked for its next trial
                self.store.set_status(self.run_id, RunStatus.FINISHED)
            return None
        return self.hand_out(proposal)

    @property
    def pending(self) -> list[Proposal]:
        """The trials handed out and not told yet, in index order (a resumed run's included)."""
        out = getattr(self.learner, "pending", None)
        if isinstance(out, dict):
            return [out[i] for i in sorted(out)]
        record = self.store.pending(self.run_id) if self.store is not None else None
        return [] if record is None else [record.proposal]

    def hand_out(self, proposal: Proposal) -> Proposal:
        """Commit ``proposal``, which ``learner.ask()`` returned, before it is handed out."""
        t0 = time.perf_counter()
        self.store.add_proposal(self.run_id, proposal)
        self.commit_seconds = time.perf_counter() - t0
        return proposal

    def check(self, outcome: Outcome, index: int | None = None):
        """The pending trial ``outcome`` answers (trial ``index``; may be left out while one is pending),
        or what :meth:`tell` would refuse; writes nothing."""
        if not isinstance(outcome, Outcome):
            raise InputError(f"tell() needs a corl.Outcome, got {type(outcome).__name__}")
        out = self.store.pending_trials(self.run_id)
        if not out:
            raise StateError("there is no pending trial to tell: run 'corl ask' first")
        if index is None and len(out) > 1:
            raise StateError(f"trials {[r.proposal.index for r in out]} are pending: name the one this outcome answers")
        pending = out[-1] if index is None else next((r for r in out if r.proposal.index == index), None)
        if pending is None:
            raise StateError(f"trial {index} is not pending (pending: {[r.proposal.index for r in out]}); "
                             "each trial is told once")
        _check_outcome(self.learner, pending.proposal, outcome)
        return pending

    def tell(self, outcome: Outcome, index: int | None = None) -> None:
        """Commit the outcome of pending trial ``index`` (may be left out while one is pending), then tell the learner.

        An outcome the learner would refuse is refused before anything is written (:meth:`check`):
        a failed demonstration (Algorithm 1 needs a successful one) leaves the store as it was.
        """
        pending = self.check(outcome, index)
        settle = getattr(type(self.learner), "settle", None)  # a speculation ends first: store and learner
        if settle is not None:                                  # move on together
            settle(self.learner)
        t0 = time.perf_counter()
        self.store.add_outcome(self.run_id, pending.index, outcome)  # committed before the learner moves on
        self.commit_seconds = time.perf_counter() - t0
        try:
            if getattr(self.learner, "try_ask", None) is None:
                self.learner.tell(outcome)
            else:
                self.learner.tell(outcome, pending.proposal.index)
        except Exception as exc:
            error = None if isinstance(exc, CorlError) else task_error(exc, pending.index)
            if error is None:  # corl's own: the learner has ended
                if self.learner.done:
                    self.store.set_status(self.run_id, RunStatus.FINISHED)
                raise
            # the task's code: the run stays open, to resume once the task is fixed or to end there
            raise TaskError(f"{error}; the store keeps all {pending.index + 1} told trials. "
                            f"{way_on(self.store, self.run_id, error)}", member=error.member, trial=error.trial,
                            detail=error.detail) from exc
        if self.learner.done:
            self.store.set_status(self.run_id, RunStatus.FINISHED)
        self.store.set_best(self.run_id, best_record(self.learner))  # what corl status reads as the learner's best

    @property
    def done(self) -> bool:
        """The learner has finished, or the run was ended at a task error (:attr:`ended`)."""
        return self.ended is not None or self.learner.done

    @property
    def best(self):
        return self.learner.best

    @property
    def history(self):
        return self.learner.history

    def run(self, task: Task, *, max_trials: int | None = None,
            callback: Callable[[Proposal, Outcome], None] | None = None, worker: bool = True):
        """ask -> ``task.rollout`` -> tell until the learner is done (or ``max_trials``).

        A task with ``rollout_in_worker = True`` (a simulator) is rolled out in a forked worker process
        (:mod:`corl.tasks.worker`) while a learner that can (CORL) computes its next step-1 or phase
        candidate meanwhile: the same trials, sooner. ``worker=False`` keeps everything in this process,
        and so does a machine where the fork fails. ``callback(proposal, outcome)`` may then run while
        that candidate is computed: let it read the proposal, the outcome and ``best``, never the task.
        """
        from corl.tasks.noisy import NoisyTask
        from corl.tasks.worker import RolloutWorker, wants_worker

        learner = self.learner
        if isinstance(task, NoisyTask):  # a w tried before reads its next values, resumed or not (and in the worker)
            task.recount(p.w for p, _ in self.history)
        rollouts = None
        # vars(): a learner of its own that speculates (CORL), not one that passes attributes on (ContextualCORL)
        if worker and wants_worker(task) and "speculative" in vars(learner):
            try:
                rollouts = RolloutWorker(task)  # forked here, ended on every way out
            except OSError:  # no fork here (process limit, memory): the same trials in this process
                rollouts = None
        if rollouts is None:
            drive(self, task, max_trials=max_trials, callback=callback, pending_hint=" in the store")
        else:
            with rollouts:
                learner.speculative = True
                try:
                    drive(self, task, max_trials=max_trials, callback=callback, pending_hint=" in the store",
                          rollout=rollouts.rollout)
                finally:
                    learner.speculative = False
                    learner.settle()  # no thread left computing on the task once run() returns
        if self.done:
            self.store.set_status(self.run_id, RunStatus.FINISHED)
        return self.best


def _snapshot(info) -> tuple:
    """What tells whether a stored run changed: its trials, outcomes and status."""
    return info.n_trials, info.n_told, info.status


def best_record(learner) -> dict | None:
    """The learner's best as JSON: ``theta``, ``return`` (its estimate), ``return_std`` (None for a reading),
    ``J``, and ``trial``, the index of the trial whose w it is (the last one with that w); None before any success."""
    best = getattr(learner, "best", None)
    if best is None:
        return None
    trial = next((p.index for p, o in reversed(learner.history) if o.success and np.array_equal(p.w, best.w)), None)
    std = getattr(best, "return_std", float("nan"))
    return {"theta": [float(v) for v in np.asarray(best.theta).reshape(-1)], "return": float(best.return_),
            "return_std": None if not np.isfinite(std) else float(std),
            "J": None if getattr(best, "J", None) is None else float(best.J), "trial": trial}


def _check_outcome(learner, proposal: Proposal, outcome: Outcome) -> None:
    """Raise what ``learner.tell(outcome)`` would raise for a refused outcome, before it is stored."""
    from corl.learner import CORL

    if isinstance(learner, CORL) and proposal.step == "demonstration" and not outcome.success:
        failed = sum(p.step == "demonstration" and not o.success for p, o in learner.history)
        if failed < learner.config.start_retries:  # one wrong reading: the learner asks the demonstration again
            return
        raise DemonstrationFailedError(
            f"the demonstration failed {failed + 1} times (start_retries={learner.config.start_retries}), so "
            "Algorithm 1 has no safe start; the last reading was not stored. Re-record the "
            "demonstration (or check the success criterion) and tell its outcome again, or start a new run"
        )


MAX_RATE_HZ = 100_000.0  # a robot's control rate is at most a few kHz; beyond this a CSV only grows


def check_rate(rate: float) -> float:
    """``rate`` (Hz) of a written trajectory, or :class:`InputError`: finite, > 0 and <= MAX_RATE_HZ."""
    try:
        value = float(rate)
    except (TypeError, ValueError):
        raise InputError(f"the rate must be a number of Hz, got {rate!r}") from None
    if not (math.isfinite(value) and 0.0 < value <= MAX_RATE_HZ):
        raise InputError(f"the rate must be a finite number of Hz in (0, {MAX_RATE_HZ:g}], got {rate}")
    return value


def trajectory_of(task: Task, w: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Times (K,) and joint positions (K, Q) a robot should follow for ``w``: ``task.reference(w, rate)``.

    Raises :class:`InputError` for a task without ``reference`` (its parameters are no joint
    trajectory: ``corl ask --raw`` writes them, labelled as such) or a ``reference`` that breaks
    its contract (:class:`corl.problem.HasReference`).
    """
    from corl.problem import check_reference

    check_rate(rate)
    reference = getattr(task, "reference", None)  # corl.problem.HasReference
    if reference is None:
        raise InputError(f"task '{task.name}' has no reference(w, rate), so corl cannot turn w into a joint "
                         "trajectory; add reference() to the task (see corl.problem.HasReference), or pass --raw "
                         "to write the raw parameters w (not a joint trajectory: never send them to a robot)")
    t, q = reference(w, rate)
    return check_reference(task, t, q, rate)


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if hasattr(obj, "value") and not isinstance(obj, (int, float, str, bool)):
        return obj.value
    return obj
