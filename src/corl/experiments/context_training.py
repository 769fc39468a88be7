"""The training scenes of ``corl bench contexts``: learned in turn by one robot, or in waves by K robots.

One robot (``robots=1``): each training context in turn, its run learning from every run before it
(the store as it stands when the run starts).

K robots: the contexts K at a time, in waves fixed by their order (wave 1: contexts 1..K, wave 2:
K+1..2K, ...). Every scene of a wave learns from the runs of the waves before it and nothing else: its
run's ``config["learned_from"]`` names exactly those runs with their told trials, read from the store
as it was when the wave began. Each new scene of a wave is learned in a forked process of its own,
into a store of its own; once the wave is done, its runs are copied into the study's store in the
contexts' order (:func:`corl.store.copy.copy_runs`, one transaction), so the store reads as if one
robot had learned them in turn from those views.

Resume (either way): a context whose run is finished in the store is kept as it is; an unfinished one
is continued exactly (:meth:`corl.session.StoredRun.open`; with K robots, in this process while the
wave's new scenes are learned); a missing one is learned.

``trial_seconds`` S: every trial also takes S seconds (after its rollout), standing for a robot's
time, as in ``corl bench parallel``.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import ExitStack, nullcontext
from pathlib import Path

import numpy as np

from corl.errors import InputError

__all__ = ["train", "waves", "check_robots", "MAX_ROBOTS"]

MAX_ROBOTS = 64  # as corl bench parallel
MAX_TRIAL_SECONDS = 3600.0


def _task(spec: str, seed: int):
    from corl.experiments.sweep import TaskSpec

    return TaskSpec(spec, seed)()


def _stored_runs(store: Path) -> list:
    """The runs of ``store`` in the order they were created; none for a missing or empty file (a
    creation that was killed before its first commit)."""
    from corl.store import RunStore
    from corl.store.records import EmptyStoreError

    if not store.exists():
        return []
    try:
        with RunStore(store, create=False, readonly=True) as ro:
            return ro.runs()
    except EmptyStoreError:
        return []


def _row(c, history, best, start: str, seconds: float) -> dict:
    return {"context": [float(v) for v in c], "trials": len(history),
            "failures": sum(not o.success for _, o in history),
            "best_return": None if best is None else float(best.return_), "start": start or "demonstration",
            "seconds": seconds}


def _same(a, b) -> bool:
    return a is not None and np.shape(a) == np.shape(b) and np.allclose(a, b, rtol=0.0, atol=1e-12)


def _run_in(runs: list, c):
    """The run of ``runs`` learned in context ``c``, or None."""
    return next((r for r in runs if _same(r.config.get("context"), c)), None)


def check_robots(robots, trial_seconds) -> tuple[int, float]:
    """``(robots, trial_seconds)`` checked: an integer in [1, MAX_ROBOTS] and a number of seconds in
    [0, 3600]; else one InputError."""
    if isinstance(robots, bool) or not isinstance(robots, (int, np.integer)) or not 1 <= robots <= MAX_ROBOTS:
        raise InputError(f"--robots must be an integer in [1, {MAX_ROBOTS}], got {robots}")
    if (isinstance(trial_seconds, bool) or not isinstance(trial_seconds, (int, float, np.floating))
            or not (math.isfinite(trial_seconds) and 0 <= trial_seconds <= MAX_TRIAL_SECONDS)):
        raise InputError(f"--trial-seconds must be a number of seconds in [0, {MAX_TRIAL_SECONDS:g}], got {trial_seconds}")
    return int(robots), float(trial_seconds)


def waves(count: int, robots: int) -> list[range]:
    """The contexts' indices K = ``robots`` at a time, in order: ``[range(0, K), range(K, 2K), ...]``."""
    return [range(start, min(start + robots, count)) for start in range(0, count, robots)]


class _RobotTime:
    """``scene`` whose every rollout also takes ``seconds`` (a robot's time); everything else is the scene's."""

    def __init__(self, scene, seconds: float) -> None:
        self._scene, self._seconds = scene, seconds

    def __getattr__(self, name):
        return getattr(self._scene, name)

    def rollout(self, w):
        outcome = self._scene.rollout(w)
        time.sleep(self._seconds)
        return outcome


def _learn(task, spec: str, seed: int, c, *, source: Path | None, into: Path, info=None, upto: dict | None = None,
           skill: dict | None = None, seconds: float = 0.0) -> dict:
    """Learn in context ``c``; its summary row. A new run learns from the runs of ``source`` (read-only;
    None: from nothing), all of them or those ``upto`` names, and is written to ``into``; ``info``: its
    run found in ``source`` (= ``into``), kept when finished, else continued. A scene that cannot be
    learned (its demonstration or its start fails, or the task raises there) gives a ``skipped`` row."""
    from corl.errors import MissingExtraError
    from corl.session import StoredRun
    from corl.store import RunStatus, RunStore, StoreError

    t0 = time.perf_counter()
    try:
        with RunStore(source, create=False, readonly=True) if source is not None else nullcontext() as ro:
            if info is not None:
                run = StoredRun.open(ro, task, info.id)
            else:
                run = StoredRun.new(task, task_spec=spec, method="CORL", seed=seed, context=c, learned_from=ro,
                                    skill=skill if ro is not None else None, upto=upto)
        if info is None or info.status is not RunStatus.FINISHED:
            with RunStore(into) as db:
                run.attach(db)
                scene = task.with_context(c)
                run.run(_RobotTime(scene, seconds) if seconds > 0 else scene)
    except (StoreError, MissingExtraError):
        raise  # the study's own files or installation, not the scene
    except Exception as exc:  # a user's family: one scene that cannot be learned is skipped (named)
        reason = f"{type(exc).__name__}: {exc}".splitlines()[0]
        return {"context": [float(v) for v in c], "skipped": reason, "seconds": time.perf_counter() - t0}
    return _row(c, run.history, run.best, getattr(run.learner, "start_kind", ""), time.perf_counter() - t0)


def _learn_alone(spec: str, seed: int, c, source: str | None, upto: dict, skill: dict | None, into: str,
                 seconds: float) -> dict:
    """One robot of a wave (in its own process): a new run in ``c`` from what ``upto`` names in ``source``."""
    return _learn(_task(spec, seed), spec, seed, np.asarray(c, dtype=float), source=None if source is None else Path(source),
                  into=Path(into), upto=upto, skill=skill, seconds=seconds)


def train(spec: str, seed: int, contexts: np.ndarray, store: Path, progress=None, skill: dict | None = None, *,
          robots: int = 1, trial_seconds: float = 0.0) -> list[dict]:
    """Learn in each context of ``contexts`` (N, k), every run in ``store``; one summary row per
    context, in their order.

    ``robots`` 1: in turn, each from the runs before it; K > 1: in waves of K, each scene of a wave in
    its own process from the runs of the waves before it (module docstring). ``progress(stage, done,
    total, row)`` after each context (with K robots: each wave's, in order, once the wave is done).
    Resumable. A scene that cannot be learned is named in its row (``skipped``) and the study goes on
    without it; when none can, InputError."""
    robots, trial_seconds = check_robots(robots, trial_seconds)
    task = _task(spec, seed)
    store = Path(store)
    foreign = [info for info in _stored_runs(store)
               if not any(_same(info.config.get("context"), c) for c in contexts)]
    if foreign:
        raise InputError(f"run {foreign[0].id} of {store} was learned in context {foreign[0].config.get('context')}, "
                         "not one of this study's: this store belongs to another study; choose another --out")
    if robots == 1:
        rows = []
        for i, c in enumerate(contexts):
            existing = _stored_runs(store)
            rows.append(_learn(task, spec, seed, c, source=store if existing else None, into=store,
                               info=_run_in(existing, c), skill=skill, seconds=trial_seconds))
            if progress is not None:
                progress("train", i + 1, len(contexts), rows[-1])
    else:
        rows = _train_waves(task, spec, seed, contexts, store, progress, skill, robots, trial_seconds)
    if all("skipped" in r for r in rows):
        raise InputError(f"no training scene could be learned; the first: context {rows[0]['context']}: "
                         f"{rows[0]['skipped']}")
    return rows


def _before(runs: list, task, earlier) -> dict:
    """What a scene of a wave learns from: run id -> told trials of the runs learned in ``earlier`` contexts."""
    return {str(r.id): int(r.n_told) for r in runs
            if r.task == task.name and any(_same(r.config.get("context"), c) for c in earlier)}


def _end_robots(pool: ProcessPoolExecutor) -> None:
    """End the pool's processes now, instead of waiting for the scenes they are learning."""
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()


def _train_waves(task, spec, seed, contexts, store: Path, progress, skill, robots: int, seconds: float) -> list[dict]:
    from corl.fleet import _start_worker

    rows: list = [None] * len(contexts)
    with ExitStack() as stack:
        folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix=".robots-", dir=store.parent)))
        pool = stack.enter_context(ProcessPoolExecutor(
            max_workers=robots, mp_context=multiprocessing.get_context("fork"), initializer=_start_worker,
            initargs=(os.getpid(),)))
        try:
            for wave in waves(len(contexts), robots):
                _wave(wave, task, spec, seed, contexts, store, skill, seconds, pool, folder, rows)
                for i in wave:
                    if progress is not None:
                        progress("train", i + 1, len(contexts), rows[i])
        except BaseException:  # Ctrl-C, a store error: the robots' scenes are lost, the waves before are stored
            _end_robots(pool)
            raise
    return rows


def _wave(wave: range, task, spec, seed, contexts, store: Path, skill, seconds: float, pool, folder: Path,
          rows: list) -> None:
    """One wave: its new scenes learned by the pool's robots from the waves before, its unfinished runs
    continued here meanwhile, then the new runs copied into ``store`` in order; each scene's row put in ``rows``."""
    from corl.store import RunStore
    from corl.store.copy import copy_runs

    existing = _stored_runs(store)
    upto = _before(existing, task, contexts[:wave.start])
    found = {i: _run_in(existing, contexts[i]) for i in wave}
    scenes = {i: folder / f"scene-{i}.corl" for i in wave if found[i] is None}
    futures = {i: pool.submit(_learn_alone, spec, seed, np.asarray(contexts[i], dtype=float).tolist(),
                              str(store) if upto else None, upto, skill, str(path), seconds)
               for i, path in scenes.items()}
    for i in wave:  # kept, or continued here while the robots learn the new scenes
        if found[i] is not None:
            rows[i] = _learn(task, spec, seed, contexts[i], source=store, into=store, info=found[i], seconds=seconds)
    for i, future in futures.items():
        rows[i] = future.result()
    learned = [path for path in scenes.values() if _stored_runs(path)]
    if learned:
        with RunStore(store) as db, ExitStack() as sources:
            copy_runs(db, [(sources.enter_context(RunStore(path, create=False, readonly=True)), run.id)
                           for path in learned for run in _stored_runs(path)])
