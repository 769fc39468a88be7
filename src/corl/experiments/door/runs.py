"""One run of the door study (Sec. VIII-B, Fig. 3): its record, the door task of a worker process,
and CORL's runs (one round of Algorithm 1). DMP+PoWER's runs are in :mod:`corl.experiments.door.dmp`.

Glossary
--------
theta   : (2,) grasp shift along the handle (m) and finger width (m), the door's theta
anchor  : the trajectory a theta is realised from; for CORL the ``w*`` its black-box step starts
          from (the result of the motion-optimization step), for DMP+PoWER the demonstration
R       : the door task's return ``1 - F / 20 N`` (F the mean wrist force)
trial   : one rollout of the black-box step (CORL's step 2, PoWER's search)
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from corl.errors import InputError
from corl.methods import make_method

__all__ = ["CORL_METHODS", "Progress", "DoorRun", "door_task", "task_settings", "digest", "corl_settings",
           "true_return", "run_corl"]

CORL_METHODS = ("CORL+PIBU", "CORL+CMA")
Progress = Callable[..., None]  # (stage, done, total, note, run=None); run: the DoorRun that just finished

_TASKS: dict[tuple, object] = {}  # one DoorTask per worker process and settings (a MuJoCo scene)


# -- tasks in worker processes ---------------------------------------------------------------------
def task_settings(task) -> dict:
    """What rebuilds ``task`` in a worker: its size and its (possibly re-timed) contact instants."""
    return {"num_control_points": int(task.spline.num_control_points), "num_steps": int(task.num_steps),
            "contact_times": tuple(float(t) for t in task.contact_times)}


def door_task(settings: dict):
    """The process's DoorTask for ``settings`` (built once: loading the scene takes ~1 s)."""
    key = tuple(sorted(settings.items()))
    if key not in _TASKS:
        from corl.tasks.door.task import DoorTask

        options = dict(settings)
        times = options.pop("contact_times", None)
        task = DoorTask(**options)
        if times is not None and not np.array_equal(times, task.contact_times):
            task = task.retimed(lambda _: np.asarray(times, dtype=float))  # phase steps moved them
        _TASKS[key] = task
    return _TASKS[key]


def digest(array: np.ndarray) -> str:
    """A short hash of ``array``'s values: the key of an anchor's safe region."""
    return hashlib.sha256(np.ascontiguousarray(array, dtype=float).tobytes()).hexdigest()[:16]


# -- one run ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DoorRun:
    """One method from one seed.

    Attributes
    ----------
    trials, failures : rollouts of the black-box step and how many failed.
    unrealisable : thetas Eq. 18 could not realise (told as failures, never rolled out).
    highest_return : largest R over all successful rollouts (NaN without a success).
    start_return : R of the policy the black-box step starts from (CORL: its w* after step 1;
        DMP+PoWER: the fitted DMP); first_return : R of the first black-box trial (NaN if it failed).
    failed_thetas : (failures, 2) theta of every failed trial.
    trial_success, trial_returns : (trials,) S and measured R of every trial in order (R NaN on a
        failure): the learning curves of Fig. 3 (:mod:`corl.experiments.door.curves`).
    final_return : the true R (no sensor error) of the policy the method returns, its best measured
        one; with ``force_noise`` the highest measured R is biased upwards, this is not.
    anchor : (n,) the trajectory the safe region of this run is realised from; anchor_times : the
        contact instants its constraints hold at (phase steps move them, Sec. VI-B).
    rollouts : all rollouts of the run; seconds : wall time of the run.
    """

    method: str
    seed: int
    trials: int
    failures: int
    unrealisable: int
    highest_return: float
    start_return: float
    first_return: float
    failed_thetas: np.ndarray
    trial_success: np.ndarray
    trial_returns: np.ndarray
    final_return: float
    best_theta: np.ndarray | None
    anchor: np.ndarray
    anchor_times: tuple
    rollouts: int
    seconds: float


def corl_settings(task, iterations: int):
    """The task's Sec. VIII-B settings with one round and ``iterations`` black-box trials (``max_rl_trials``)."""
    preset = task.method_settings()
    return replace(preset, corl=replace(preset.corl, max_rounds=1, max_rl_trials=iterations))


def true_return(outcome) -> float:
    """R of a successful door Outcome from the true mean force (``info["force_mean"]``), no sensor error."""
    from corl.tasks.door.task import return_of_force

    return return_of_force(outcome.info["force_mean"])


def run_corl(method: str, seed: int, iterations: int, *, task=None) -> DoorRun:
    """One round of Algorithm 1 (motion optimization, then ``iterations`` black-box trials)."""
    if method not in CORL_METHODS:
        raise InputError(f"unknown CORL method '{method}' for the door; choose one of {', '.join(CORL_METHODS)}")
    t0 = time.perf_counter()
    task = task or door_task({})
    learner = make_method(method, task, seed=seed, settings=corl_settings(task, iterations))
    learner.run()
    history = learner.history
    rl = [(p, o) for p, o in history if p.step == "reinforcement"]
    before = [(p, o) for p, o in history if p.step != "reinforcement" and o.success]
    anchor_p, anchor_o = before[-1]  # step 1 stops at its first failure: the last success is w*
    ok = [o.return_ for _, o in history if o.success]
    fails = [p.theta for p, o in rl if not o.success]
    best = learner.best
    chosen = [o for p, o in history if best is not None and o.success and np.array_equal(p.w, best.w)]
    return DoorRun(
        method=method, seed=seed, trials=len(rl), failures=len(fails), unrealisable=learner.unrealisable,
        highest_return=max(ok) if ok else math.nan, start_return=float(anchor_o.return_),
        first_return=float(rl[0][1].return_) if rl and rl[0][1].success else math.nan,
        failed_thetas=np.array(fails, dtype=float).reshape(-1, 2),
        trial_success=np.array([o.success for _, o in rl], dtype=bool),
        trial_returns=np.array([o.return_ if o.success else math.nan for _, o in rl], dtype=float),
        final_return=true_return(chosen[-1]) if chosen else math.nan,
        best_theta=None if learner.best is None else np.asarray(learner.best.theta, dtype=float),
        anchor=np.asarray(anchor_p.w, dtype=float), anchor_times=tuple(learner.task.contact_times.tolist()),
        rollouts=len(history), seconds=time.perf_counter() - t0)

