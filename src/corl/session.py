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
from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np

from corl.errors import DemonstrationFailedError, InputError, StateError
from corl.loop import drive
from corl.problem import Outcome, Proposal, Task
from corl.store import RunStatus, RunStore, StoreError, replay

__all__ = ["StoredRun", "trajectory_of", "check_rate", "MAX_RATE_HZ"]


def _build(task: Task, method: str, seed: int, corl_overrides: dict | None = None):
    """The learner; ``corl_overrides`` replace fields of the task's CORLConfig (``--rollout-every-step``)."""
    from dataclasses import replace

    from corl.methods import make_method, settings_for

    if not corl_overrides:
        return make_method(method, task, seed=seed)
    settings = settings_for(task)  # the same defaults as without overrides (a user's task: fitted GPs)
    return make_method(method, task, seed=seed, settings=replace(settings, corl=replace(settings.corl, **corl_overrides)))


class StoredRun:
    """An ask/tell learner whose trials are committed to ``store`` under ``run_id``."""

    def __init__(self, learner, store: RunStore, run_id: int) -> None:
        self.learner = learner
        self.store = store
        self.run_id = run_id

    # -- creating and reopening ----------------------------------------------------------------
    @classmethod
    def start(cls, store: RunStore, task: Task, *, task_spec: str, method: str, seed: int,
              corl_overrides: dict | None = None) -> "StoredRun":
        """A new run of ``method`` on ``task`` (``task_spec`` is how the command line named it).

        ``corl_overrides`` (e.g. ``{"rollout_every_step": False}``) replace fields of the task's
        CORLConfig; they are stored with the run and applied again when it is reopened.
        """
        learner = _build(task, method, seed, corl_overrides)
        config = {"task_spec": task_spec, "task_name": task.name}
        if corl_overrides:
            config["corl_overrides"] = dict(corl_overrides)
        cfg = getattr(learner, "config", None)
        if cfg is not None:
            config["learner"] = _plain(asdict(cfg))
        run_id = store.create_run(task=task.name, method=method, seed=seed, config=config)
        return cls(learner, store, run_id)

    @classmethod
    def open(cls, store: RunStore, task: Task, run_id: int | None = None) -> "StoredRun":
        """Reopen a run (default: the latest one) and replay its trials into a fresh learner."""
        info = store.run(run_id) if run_id is not None else store.latest_run()
        if info is None:
            raise StoreError(f"{store.path} holds no run yet; start one with 'corl run' or 'corl ask --task ...'")
        if info.task != task.name:
            raise InputError(f"run {info.id} in {store.path} is for task '{info.task}', but the task given is "
                             f"'{task.name}'; name the same task as when the run was started")
        learner = _build(task, info.method, 0 if info.seed is None else int(info.seed),
                         info.config.get("corl_overrides"))
        replay(learner, store, info.id)
        return cls(learner, store, info.id)

    # -- ask / tell ----------------------------------------------------------------------------
    def ask(self) -> Proposal:
        proposal = self.learner.ask()
        self.store.add_proposal(self.run_id, proposal)  # committed before it is handed out
        return proposal

    def tell(self, outcome: Outcome) -> None:
        """Commit the outcome of the pending trial, then tell the learner.

        An outcome the learner would refuse is refused before anything is written: a failed
        demonstration (Algorithm 1 needs a successful one) leaves the store as it was.
        """
        if not isinstance(outcome, Outcome):
            raise InputError(f"tell() needs a corl.Outcome, got {type(outcome).__name__}")
        pending = self.store.pending(self.run_id)
        if pending is None:
            raise StateError("there is no pending trial to tell: run 'corl ask' first")
        _check_outcome(self.learner, pending.proposal, outcome)
        self.store.add_outcome(self.run_id, pending.index, outcome)  # committed before the learner moves on
        try:
            self.learner.tell(outcome)
        finally:
            if self.learner.done:
                self.store.set_status(self.run_id, RunStatus.FINISHED)

    @property
    def done(self) -> bool:
        return self.learner.done

    @property
    def best(self):
        return self.learner.best

    @property
    def history(self):
        return self.learner.history

    def run(self, task: Task, *, max_trials: int | None = None,
            callback: Callable[[Proposal, Outcome], None] | None = None):
        """ask -> ``task.rollout`` -> tell until the learner is done (or ``max_trials``)."""
        drive(self, task, max_trials=max_trials, callback=callback, pending_hint=" in the store")
        if self.done:
            self.store.set_status(self.run_id, RunStatus.FINISHED)
        return self.best


def _check_outcome(learner, proposal: Proposal, outcome: Outcome) -> None:
    """Raise what ``learner.tell(outcome)`` would raise for a refused outcome, before it is stored."""
    from corl.learner import CORL

    if isinstance(learner, CORL) and proposal.step == "demonstration" and not outcome.success:
        raise DemonstrationFailedError(
            "the demonstration failed, so Algorithm 1 has no safe start; nothing was stored. Re-record the "
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
