"""Scenes through ``corl serve``: one server, one store, runs in many contexts (issue 33).

A robot says its scene when it asks (``POST /ask {"context": [...]}``); the server then serves the
run of that scene, as ``corl ask --context`` does from the shell:

* the run it serves now, when that run is in the scene and not finished;
* else the store's latest unfinished run in that scene (one the server, or ``corl ask``, left there
  when the robot moved on), reopened;
* else a new run in the scene, learning from every run the store holds (:mod:`corl.contexts`).

One trial is pending at a time, across scenes: asking in another scene while a trial is pending is
refused (409) until that trial is told, so a robot never has two motions out at once and every
``tell`` has one run to go to. A run the robot leaves unfinished stays as it is, and goes on when the
robot comes back to its scene (docs/project/decisions.md, "Scenes through corl serve").

This module holds what the server needs of a scene: the ``context`` of a request checked against
the task's box (:func:`requested_context`), a run's scene (:func:`run_context`), where to find or
start the run of a scene (:func:`run_for_scene`) and the runs a status lists (:func:`runs_summary`).
"""

from __future__ import annotations

import numpy as np

from corl.errors import InputError

__all__ = ["requested_context", "run_context", "same_scene", "run_for_scene", "runs_summary"]


def requested_context(task, value) -> np.ndarray:
    """The body's ``context`` as a point (k,) of the task's context box, or one :class:`InputError`:
    a task without contexts, not a list of k numbers, outside the box."""
    from corl.contexts import context_task
    from corl.problem import check_theta

    try:
        context_task(task)
    except InputError as exc:
        raise InputError(f"{exc}; this server's task learns in one scene: ask without 'context'") from None
    k = task.context_bounds.dim
    if not isinstance(value, list) or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in value):
        raise InputError(f"'context' must be a list of {k} number{'s' if k > 1 else ''}, e.g. {[0.0] * k}, "
                         f"got {value!r:.60}")
    if len(value) != k:
        raise InputError(f"'context' has {len(value)} number{'s' if len(value) != 1 else ''}, but task "
                         f"'{task.name}' has {k} context coordinate{'s' if k > 1 else ''}: {_box(task)}")
    c = np.array(value, dtype=float)
    if not task.context_bounds.contains(c):
        raise InputError(f"'context' {c.tolist()} is outside {_box(task)}; corl learns the skill inside it only")
    return check_theta(c, task.context_bounds, task=task.name, what="context")


def _box(task) -> str:
    b = task.context_bounds
    labels = getattr(task, "context_labels", None) or [f"c{i + 1}" for i in range(b.dim)]
    coords = ", ".join(f"{label} in [{lo:g}, {hi:g}]" for label, lo, hi in zip(labels, b.lower, b.upper))
    return f"the context box of task '{task.name}': {coords}"


def run_context(info) -> np.ndarray | None:
    """The scene a stored run learned in (``config["context"]``), or None for a task without contexts."""
    c = (info.config or {}).get("context")
    return None if c is None else np.asarray(c, dtype=float).reshape(-1)


def same_scene(info, c) -> bool:
    rc = run_context(info)
    return rc is not None and rc.shape == np.shape(c) and bool(np.array_equal(rc, c))


def run_for_scene(db, task, task_spec: str, c, *, method: str, seed: int):
    """The run to serve in scene ``c``: the store's latest unfinished run there, reopened, or a new one that
    learns from every run of the store; ``(StoredRun attached to db, created)``."""
    from corl.session import StoredRun
    from corl.store import RunStatus

    for info in reversed(db.runs()):
        if info.status is not RunStatus.FINISHED and info.task == task.name and same_scene(info, c):
            session = StoredRun.open(db, task, info.id)
            if not session.done:
                return session.attach(db), False
    return StoredRun.new(task, task_spec=task_spec, method=method, seed=seed, context=c, learned_from=db).attach(db), True


def runs_summary(db) -> list[dict]:
    """Each run of the store with its scene, for ``GET /status`` and the dashboard."""
    return [{"run": r.id, "context": None if run_context(r) is None else run_context(r).tolist(),
             "trials": r.n_trials, "told": r.n_told, "status": r.status.value} for r in db.runs()]
