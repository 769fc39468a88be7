"""K simulated robots: a stored run's trials rolled out in K worker processes at once (``corl run --robots K``).

:func:`run_fleet` keeps as many trials out as the learner hands out (up to K, :meth:`StoredRun.try_ask`),
each in a forked worker process (``backend="local"``), and tells each outcome as its process ends,
filling up again after every tell. A resumed run's pending trials (a crash with K out) go out first,
as they are: none is lost, none is proposed again. ``trial_seconds`` adds the time a real robot or a
slow simulator spends on each trial (``corl bench parallel``).

The task is forked into each worker, so its rollout must be a pure function of ``w`` (a simulator);
a real robot's task is driven through ``corl serve`` or ``corl ask``/``corl tell`` instead. Only the
local backend exists: Ray and Dask are not done (InputError names them).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Callable

from corl import checks
from corl.errors import InputError, RolloutError
from corl.problem import Outcome, Proposal, Task

__all__ = ["run_fleet", "BACKENDS"]

BACKENDS = ("local",)  # processes on this machine; Ray actors and Dask workers are not done
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


def check_backend(backend: str) -> str:
    if backend not in BACKENDS:
        raise InputError(f"--backend {backend!r} is not available: corl runs several robots as local processes "
                         f"only (--backend local); Ray and Dask backends are not done yet")
    return backend


def run_fleet(session, task: Task, *, robots: int, backend: str = "local", trial_seconds: float = 0.0,
              callback: Callable[[Proposal, Outcome], None] | None = None) -> int:
    """Roll out ``session``'s trials (a :class:`corl.session.StoredRun`) on ``robots`` worker processes
    until its learner is done; returns the number of trials told. A rollout that raises is a
    :class:`RolloutError` (its trial, and those still out, stay pending in the store: resume goes on)."""
    global _TASK
    robots = checks.integer("robots", robots, low=1)
    check_backend(backend)
    if not (isinstance(trial_seconds, (int, float)) and 0 <= trial_seconds < float("inf")):
        raise InputError(f"trial_seconds must be a finite number >= 0, got {trial_seconds!r}")
    _TASK, told, running = task, 0, {}
    context = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(max_workers=robots, mp_context=context, initializer=_start_worker,
                             initargs=(os.getpid(),)) as pool:
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
