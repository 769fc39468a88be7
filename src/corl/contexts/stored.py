"""What a run store has learned across contexts: the data and the anchors of a :class:`Skill`.

Every run of a task with contexts records its context with the run (``config["context"]``), so
one store holds many scenes and every trial's context is known: the context of its run. A skill
is read from the runs of one task:

* data: per run, the last trial of each distinct theta (the step-1 trials of a round share the
  round's theta*; the last one is the motion it converged to), in its run's context;
* anchors: per run, the successful trial with the highest return (``w*, theta*``).

Runs are read in the order they were created; ``before`` keeps only the runs created before a
given run, which is what that run learned from (exact resume).
"""

from __future__ import annotations

import os

import numpy as np

from corl.contexts.models import Anchor, ContextData
from corl.errors import InputError
from corl.problem import Task
from corl.store import RunStore

__all__ = ["learned", "run_context"]


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


def learned(store, task: Task, *, before: int | None = None) -> tuple[ContextData, list[Anchor]]:
    """``(data, anchors)`` of every run of ``task`` in ``store`` (a path or an open RunStore)."""
    if isinstance(store, (str, os.PathLike)):
        with RunStore(store, create=False, readonly=True) as opened:
            return learned(opened, task, before=before)
    m, k = task.theta_bounds.dim, task.context_bounds.dim
    data = ContextData.empty(m, k)
    anchors: list[Anchor] = []
    for info in store.runs():
        if info.task != task.name or (before is not None and info.id >= before):
            continue
        c = run_context(info, k)
        if c is None:
            continue
        last: dict[bytes, tuple] = {}
        best = None
        for record in store.trials(info.id):
            if record.outcome is None:
                continue
            p, o = record.proposal, record.outcome
            last[np.asarray(p.theta, dtype=float).tobytes()] = (p.theta, o)
            if o.success and (best is None or o.return_ > best[2]):
                best = (p.w, p.theta, float(o.return_))
        for theta, o in last.values():
            data = data.add(theta, c, o.success, o.return_ if o.success else None)
        if best is not None:
            anchors.append(Anchor(c, np.asarray(best[0], dtype=float), np.asarray(best[1], dtype=float), best[2]))
    return data, anchors
