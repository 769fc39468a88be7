"""What a run store has learned across contexts: the data and the anchors of a :class:`Skill`.

Every run of a task with contexts records its context with the run (``config["context"]``), so
one store holds many scenes and every trial's context is known: the context of its run. A skill
is read from the runs of one task:

* data: per run, one point per distinct theta: a success with the best return seen there when any
  trial at that theta succeeded (S depends on theta, Sec. IV; a failed step-1 motion at theta*
  says the path failed, not theta*), else a failure;
* anchors: per run, the successful trial with the highest return (``w*, theta*``);
* failed motions: the ``w`` of every failed trial in a given scene, never proposed there again.

A run learned in a context records exactly what it learned from (``config["learned_from"]``:
run id -> told trials), so reopening it reads the same data however the store grew since.
"""

from __future__ import annotations

import os

import numpy as np

from corl.contexts.models import Anchor, ContextData
from corl.errors import InputError
from corl.problem import Task
from corl.store import RunStore

__all__ = ["learned", "run_context", "snapshot", "failed_motions"]


def run_context(info, k: int) -> np.ndarray | None:
    """The context (k,) a stored run was learned in, or None for a run without one."""
    c = info.config.get("context")
    if c is None:
        return None
    c = np.asarray(c, dtype=float).reshape(-1)
    if c.shape != (k,) or not np.all(np.isfinite(c)):
        raise InputError(f"run {info.id} records the context {info.config.get('context')!r}, but the task's contexts "
                         f"have {k} coordinates; name the task the store was learned with")
    return c


def _open(store):
    return RunStore(store, create=False, readonly=True) if isinstance(store, (str, os.PathLike)) else None


def _runs(store, task: Task, upto: dict | None):
    """``(info, c, told trial records)`` of the runs of ``task`` with a context; ``upto`` keeps only the
    runs it names and their first ``upto[id]`` told trials."""
    k = task.context_bounds.dim
    for info in store.runs():
        if info.task != task.name or (upto is not None and str(info.id) not in upto):
            continue
        c = run_context(info, k)
        if c is None:
            continue
        records = [r for r in store.trials(info.id) if r.outcome is not None]
        if upto is not None:
            records = records[: int(upto[str(info.id)])]
        yield info, c, records


def snapshot(store, task: Task) -> dict[str, int]:
    """What a new run in a context learns from: run id -> told trials, for every run of ``task``."""
    opened = _open(store)
    if opened is not None:
        with opened:
            return snapshot(opened, task)
    return {str(info.id): len(records) for info, _, records in _runs(store, task, None)}


def learned(store, task: Task, *, upto: dict | None = None) -> tuple[ContextData, list[Anchor]]:
    """``(data, anchors)`` of the runs of ``task`` in ``store`` (a path or an open RunStore): every run,
    or exactly what ``upto`` (:func:`snapshot`) names."""
    opened = _open(store)
    if opened is not None:
        with opened:
            return learned(opened, task, upto=upto)
    m, k = task.theta_bounds.dim, task.context_bounds.dim
    data = ContextData.empty(m, k)
    anchors: list[Anchor] = []
    for info, c, records in _runs(store, task, upto):
        per_theta: dict[bytes, list] = {}
        best = None
        for record in records:
            p, o = record.proposal, record.outcome
            theta = np.asarray(p.theta, dtype=float).reshape(-1)
            if theta.shape != (m,):
                raise InputError(f"run {info.id} of {getattr(store, 'path', store)} has thetas of {theta.size} numbers, "
                                 f"the task '{task.name}' {m}; name the task the store was learned with")
            entry = per_theta.setdefault(theta.tobytes(), [theta, False, -np.inf])
            if o.success:
                entry[1], entry[2] = True, max(entry[2], float(o.return_))
                if best is None or o.return_ > best[2]:
                    best = (p.w, theta, float(o.return_))
        for theta, success, r in per_theta.values():
            data = data.add(theta, c, success, r if success else None)
        if best is not None:
            anchors.append(Anchor(c, np.asarray(best[0], dtype=float), best[1], best[2]))
    return data, anchors


def failed_motions(store, task: Task, context, *, upto: dict | None = None) -> list[np.ndarray]:
    """The ``w`` of every failed trial in scene ``context`` (the runs ``upto`` names, or all)."""
    opened = _open(store)
    if opened is not None:
        with opened:
            return failed_motions(opened, task, context, upto=upto)
    c = np.asarray(context, dtype=float)
    return [np.asarray(r.proposal.w, dtype=float) for _, rc, records in _runs(store, task, upto)
            if rc.shape == c.shape and np.array_equal(rc, c) for r in records if not r.outcome.success]
