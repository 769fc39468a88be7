"""K simulated robots: a stored run's trials rolled out in K worker processes at once (``corl run --robots K``).

:func:`run_fleet` keeps as many trials out as the learner hands out (up to K, :meth:`StoredRun.try_ask`),
each in a forked worker process (``backend="local"``), and tells each outcome as its process ends,
filling up again after every tell. A resumed run's pending trials (a crash with K out) go out first,
as they are: none is lost, none is proposed again. ``trial_seconds`` adds the time a real robot or a
slow simulator spends on each trial (``corl bench parallel``).

The task is forked into each worker, so its rollout must be a pure function of ``w`` (a simulator);
a real robot's task is driven through ``corl serve`` or ``corl ask``/``corl tell`` instead.
``backend="ray"``: K Ray actors (a local Ray of K CPUs, :func:`corl.experiments.backends.cluster`),
each loading the task from its spec and seed (or, without a spec, unpickling the task) once and
rolling out the trials sent to it. ``backend="dask"``: the trials as Dask tasks on a local cluster of
K single-threaded worker processes; each worker loads the task from its spec and seed once (a task
without a spec is scattered to every worker once). With ``address`` both join a running cluster
instead (``ray start --head`` / ``dask scheduler``), whose workers must have corl and the task's
code installed (Dask workers with one thread each: a worker's threads would share its task); at most
K trials are out whatever its size.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import queue
import signal
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, ThreadPoolExecutor, wait
from contextlib import ExitStack
from importlib.util import find_spec
from typing import Callable

from corl import checks
from corl.errors import InputError, MissingExtraError, RolloutError
from corl.problem import Outcome, Proposal, Task

__all__ = ["run_fleet", "BACKENDS"]

BACKENDS = ("local", "ray", "dask")  # processes on this machine, Ray actors, or Dask workers
_TASK: Task | None = None  # the task the workers fork with (set before the pool starts them)


def _start_worker(parent: int) -> None:
    """A worker: Ctrl-C is the parent's; killed with the parent (it holds a copy of the store's writer lock)."""
    from corl.tasks.worker import _die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_parent(parent)


def _rollout(w, seconds: float):
    outcome = _TASK.rollout(w)
    if seconds > 0:
        time.sleep(seconds)
    return outcome


def check_backend(backend: str, address: str | None = None) -> str:
    if backend not in BACKENDS:
        raise InputError(f"--backend {backend!r} is not available: corl runs several robots as local processes "
                         f"(--backend local), Ray actors (--backend ray) or Dask workers (--backend dask)")
    if address is not None and backend == "local":
        raise InputError(f"--address {address!r} joins a Ray or Dask cluster: add --backend ray or --backend dask")
    if backend == "ray" and find_spec("ray") is None:
        raise MissingExtraError("--backend ray needs Ray: pip install 'corl-skills[ray]'")
    if backend == "dask" and find_spec("distributed") is None:
        raise MissingExtraError("--backend dask needs Dask: pip install 'corl-skills[dask]'")
    return backend


def _picklable(task: Task, backend: str) -> None:
    try:
        pickle.dumps(task)
    except Exception as exc:
        raise InputError(f"--backend {backend} sends the task to its workers, and it cannot be pickled "
                         f"({type(exc).__name__}: {exc}); give its spec, or use --backend local") from exc


class _RayRobot:
    """One robot on Ray: the task, loaded once, and its rollouts."""

    def __init__(self, task_spec, seed, task) -> None:
        from corl.tasks.registry import load_task

        self.task = load_task(task_spec, seed=seed) if task_spec is not None else task

    def rollout(self, w, seconds: float):
        outcome = self.task.rollout(w)
        if seconds > 0:
            time.sleep(seconds)
        return outcome


class _ThreadedPool:
    """``submit(fn, w, seconds)`` -> a concurrent.futures.Future: a thread per robot waits on the cluster's
    own future (``_call``). ``fn`` is ignored: the cluster's workers roll out their own task."""

    def submit(self, fn, w, seconds):
        return self.threads.submit(self._call, w, seconds)


class _RayPool(_ThreadedPool):
    """K Ray actors, each with the task loaded once; a robot's thread waits on a free actor's rollout."""

    def __init__(self, stack: ExitStack, task: Task, robots: int, task_spec: str | None, seed: int,
                 address: str | None = None) -> None:
        from corl.experiments.backends import cluster

        if task_spec is None:
            _picklable(task, "ray")
        stack.enter_context(cluster("ray", robots, address))
        import ray

        actor = ray.remote(num_cpus=1)(_RayRobot)
        self.ray, self.free = ray, queue.SimpleQueue()
        for _ in range(robots):
            self.free.put(actor.remote(task_spec, seed, task if task_spec is None else None))
        self.threads = stack.enter_context(ThreadPoolExecutor(max_workers=robots))

    def _call(self, w, seconds):
        robot = self.free.get()
        try:
            return self.ray.get(robot.rollout.remote(w, seconds))
        finally:
            self.free.put(robot)


_LOADED: dict = {}  # on a Dask worker: the tasks it loaded, by (spec, seed)


def _dask_rollout(task_spec, seed, task, w, seconds: float):
    """One trial on a Dask worker: the task loaded from its spec once per worker process (or given)."""
    if task is None:
        if (task_spec, seed) not in _LOADED:
            from corl.tasks.registry import load_task

            _LOADED[(task_spec, seed)] = load_task(task_spec, seed=seed)
        task = _LOADED[(task_spec, seed)]
    outcome = task.rollout(w)
    if seconds > 0:
        time.sleep(seconds)
    return outcome


class _DaskPool(_ThreadedPool):
    """Dask workers, each loading the task once (:func:`_dask_rollout`); a robot's thread waits on its Dask future."""

    def __init__(self, stack: ExitStack, task: Task, robots: int, task_spec: str | None, seed: int,
                 address: str | None = None) -> None:
        from corl.experiments.backends import cluster

        if task_spec is None:
            _picklable(task, "dask")
        stack.enter_context(cluster("dask", robots, address))
        from distributed import get_client

        self.client, self.spec, self.seed = get_client(), task_spec, seed
        self.task = None if task_spec is not None else self.client.scatter(task, broadcast=True)
        self.threads = stack.enter_context(ThreadPoolExecutor(max_workers=robots))

    def _call(self, w, seconds):
        return self.client.submit(_dask_rollout, self.spec, self.seed, self.task, w, seconds, pure=False).result()


def run_fleet(session, task: Task, *, robots: int, backend: str = "local", trial_seconds: float = 0.0,
              callback: Callable[[Proposal, Outcome], None] | None = None, task_spec: str | None = None,
              seed: int = 0, address: str | None = None) -> int:
    """Roll out ``session``'s trials (a :class:`corl.session.StoredRun`) on ``robots`` worker processes
    (or Ray actors or Dask workers, which load ``task_spec`` with ``seed``; on the cluster at ``address``
    if given) until its learner is done; returns the number of trials told. A rollout that raises is a
    :class:`RolloutError` (its trial, and those still out,
    stay pending in the store: resume goes on)."""
    global _TASK
    robots = checks.integer("robots", robots, low=1)
    check_backend(backend, address)
    if not (isinstance(trial_seconds, (int, float)) and 0 <= trial_seconds < float("inf")):
        raise InputError(f"trial_seconds must be a finite number >= 0, got {trial_seconds!r}")
    _TASK, told, running = task, 0, {}
    with ExitStack() as stack:
        if backend in ("ray", "dask"):
            pool = (_RayPool if backend == "ray" else _DaskPool)(stack, task, robots, task_spec, seed, address)
        else:
            pool = stack.enter_context(ProcessPoolExecutor(
                max_workers=robots, mp_context=multiprocessing.get_context("fork"), initializer=_start_worker,
                initargs=(os.getpid(),)))
        def send(proposal: Proposal) -> None:
            running[pool.submit(_rollout, proposal.w, float(trial_seconds))] = proposal

        def fill() -> None:
            while len(running) < robots and not session.done and (proposal := session.try_ask()) is not None:
                send(proposal)

        for proposal in session.pending:  # resumed with trials out: they go out again first
            send(proposal)
        fill()
        while running:
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in sorted(finished, key=lambda f: running[f].index):
                proposal = running.pop(future)
                try:
                    outcome = future.result()
                except Exception as exc:
                    for other in running:
                        other.cancel()
                    raise RolloutError(f"the rollout of trial {proposal.index} ({proposal.step}) raised "
                                       f"{type(exc).__name__}: {exc}. It stays pending in the store with "
                                       f"{len(running)} other(s): fix the task and resume") from exc
                if not isinstance(outcome, Outcome):
                    raise RolloutError(f"task.rollout must return a corl.Outcome, got {type(outcome).__name__}; "
                                       f"trial {proposal.index} stays pending")
                session.tell(outcome, proposal.index)
                told += 1
                if callback is not None:
                    callback(proposal, outcome)
                fill()
    _TASK = None
    return told
