"""The door benchmark of Sec. VIII-B, Fig. 3: CORL+PIBU, CORL+CMA and DMP+PoWER on the door task.

Glossary
--------
theta        : (2,) grasp shift along the handle (m) and finger width (m), the door's theta
safe region  : the thetas whose realisation (Eq. 18 from an anchor trajectory) opens the door,
               measured on a grid over ``task.theta_bounds`` (:func:`safe_region`)
anchor       : the trajectory a theta is realised from; for CORL the ``w*`` its black-box step
               starts from (the result of the motion-optimization step), for DMP+PoWER the
               demonstration
R            : the door task's return ``1 - F / 20 N`` (F the mean wrist force); the paper's R is
               in other units, so only the trend compares
trial        : one rollout of the black-box step (CORL's step 2, PoWER's search)

Metrics of one run (the rows of Fig. 3; mean and standard deviation over seeds):

* highest return : the largest R over every successful rollout of the run (demonstration and
  motion-optimization rollouts included: they are the policy the learner starts from);
* failure rate   : failed trials / trials of the black-box step;
* max distance   : the largest Euclidean distance in theta (m, both coordinates unscaled) from a
  failed trial to the nearest safe grid point; 0 for a run without failures.

Setup of the runs (beyond the paper, which states no budget for the door):

* CORL runs the full Algorithm 1 for one round (``CORLConfig(max_rounds=1)``): motion
  optimization from the demonstration, then at most ``iterations`` black-box trials. PIBU may
  stop earlier by its own rule (its next point within 1e-3 of a sampled one).
* A theta the projection cannot realise is told to the black-box method as a failure without a
  rollout (see :mod:`corl.learner`); those are counted apart (``unrealisable``), not as failures.
* DMP+PoWER: PoWER over the 96 parameters of a DMP fitted to the demonstration
  (:mod:`corl.experiments.door_dmp`); its theta is measured on the executed reference, and its
  trajectory is not a projection from the anchor, so its distance to the safe region is only
  indicative.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from corl.errors import InputError

__all__ = ["CORL_METHODS", "DOOR_METHODS", "PAPER_FIG3", "DoorRun", "SafeRegion", "DoorBench", "safe_region",
           "distance_to_safe", "true_return", "run_corl", "run_one", "door_sweep", "aggregate"]

CORL_METHODS = ("CORL+PIBU", "CORL+CMA")
DOOR_METHODS = CORL_METHODS + ("DMP+PoWER",)
PAPER_FIG3 = {  # highest return (mean, std), failure rate (mean, std), max distance (mean, std)
    "CORL+PIBU": (0.45, 0.032, 0.157, 0.021, 0.0146, 0.006),
    "CORL+CMA": (0.41, 0.017, 0.190, 0.102, 0.0358, 0.030),
}
Progress = Callable[..., None]  # (stage, done, total, note, run=None); run: the DoorRun that just finished

_TASKS: dict[tuple, object] = {}  # one DoorTask per worker process and settings (a MuJoCo scene)


# -- tasks in worker processes ---------------------------------------------------------------------
def _task_settings(task) -> dict:
    """What rebuilds ``task`` in a worker: its size and its (possibly re-timed) contact instants."""
    return {"num_control_points": int(task.spline.num_control_points), "num_steps": int(task.num_steps),
            "contact_times": tuple(float(t) for t in task.contact_times)}


def _door_task(settings: dict):
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


def _digest(array: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(array, dtype=float).tobytes()).hexdigest()[:16]


# -- the ground truth: the safe region over theta -----------------------------------------------------
@dataclass(frozen=True)
class SafeRegion:
    """Success of a dense grid over theta.

    Attributes
    ----------
    theta1 : (n1,) grid of the grasp shift (m); theta2 : (n2,) grid of the finger width (m).
    success : (n1, n2) bool, the realised theta opened the door.
    realised : (n1, n2) bool, Eq. 18 found a feasible trajectory (an unrealised theta is unsafe).
    key : the cache key (task settings, grid, anchor, library versions).
    """

    theta1: np.ndarray
    theta2: np.ndarray
    success: np.ndarray
    realised: np.ndarray
    key: str

    @property
    def points(self) -> np.ndarray:
        """(n1 n2, 2) every grid point, row-major like ``success.ravel()``."""
        T1, T2 = np.meshgrid(self.theta1, self.theta2, indexing="ij")
        return np.column_stack([T1.ravel(), T2.ravel()])

    @property
    def safe_points(self) -> np.ndarray:
        """(k, 2) the successful grid points."""
        return self.points[self.success.ravel()]

    @property
    def spacing(self) -> np.ndarray:
        """(2,) grid step per coordinate: the resolution of :func:`distance_to_safe`."""
        return np.array([np.ptp(self.theta1) / max(len(self.theta1) - 1, 1),
                         np.ptp(self.theta2) / max(len(self.theta2) - 1, 1)])


def safe_region(task, n1: int = 25, n2: int = 15, *, anchor: np.ndarray | None = None,
                cache: str | Path | None = None, jobs: int = 2, backend: str = "loky",
                address: str | None = None, progress: Progress | None = None) -> SafeRegion:
    """The safe region over theta from a dense sweep (about 0.4 s per grid point).

    Each theta of an ``n1 x n2`` grid over ``task.theta_bounds`` is realised from ``anchor`` with
    Eq. 18, exactly as the learner does it (:func:`corl.realise.realise`: the task's projection
    metric, continuation when the direct projection is infeasible), rolled out, and its success
    recorded: :func:`corl.experiments.sweep.sweep_task`, the code behind ``corl sweep``.

    Parameters
    ----------
    task : a :class:`corl.tasks.door.DoorTask` (only its settings travel to the workers).
    n1, n2 : grid points along the grasp shift and the finger width.
    anchor : (n,) the trajectory thetas are realised from; default the demonstration's ``w0``.
    cache : folder for ``door_safe_region_<key>.npz``; the key covers the task's settings, the
        grid, the anchor and :func:`corl.versions.library_versions`.
    jobs, backend, address : workers and where they run (:func:`corl.experiments.backends.cluster`).
    progress : ``(stage, done, total, note)``, called as chunks of the grid finish.
    """
    from corl.experiments.sweep import sweep_task
    from corl.versions import library_versions

    if n1 < 2 or n2 < 2:
        raise InputError(f"the safe-region grid needs at least 2 x 2 points, got {n1} x {n2}")
    settings = _task_settings(task)
    anchor = np.asarray(task.demonstration().w if anchor is None else anchor, dtype=float)
    bounds = task.theta_bounds
    theta1 = np.linspace(bounds.lower[0], bounds.upper[0], n1)
    theta2 = np.linspace(bounds.lower[1], bounds.upper[1], n2)
    key_source = {"task": settings, "lower": bounds.lower.tolist(), "upper": bounds.upper.tolist(),
                  "grid": [n1, n2], "anchor": _digest(anchor), "versions": library_versions()}
    key = hashlib.sha256(json.dumps(key_source, sort_keys=True).encode()).hexdigest()[:16]
    path = None if cache is None else Path(cache) / f"door_safe_region_{key}.npz"
    if path is not None and path.exists():
        with np.load(path) as f:
            return SafeRegion(f["theta1"], f["theta2"], f["success"], f["realised"], key)

    def tick(done: int, total: int, safe: int) -> None:
        if progress is not None:
            progress("safe region", done, total, f"{safe} safe so far")

    theta_anchor = np.asarray(task.demonstration().theta, dtype=float)  # step 1 keeps theta: w* realises theta0
    grid = sweep_task(partial(_door_task, settings), (n1, n2), anchor=anchor, theta_anchor=theta_anchor,
                      jobs=jobs, backend=backend, address=address, progress=tick)
    success, realised = grid.success, grid.realised
    region = SafeRegion(theta1, theta2, success, realised, key)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(path.stem + ".tmp.npz")
        np.savez(tmp, theta1=theta1, theta2=theta2, success=region.success, realised=region.realised,
                 key=np.array(json.dumps(key_source, sort_keys=True)))
        tmp.replace(path)
    return region


def distance_to_safe(theta, grid: SafeRegion) -> float:
    """Euclidean distance in theta (m; the two coordinates unscaled) to the nearest safe grid point.

    The paper reports one number per failure in theta units; this is its measurement against the
    grid. Its resolution is half a grid step (``grid.spacing``): a failure just outside the safe
    region is up to that far from the nearest safe grid point. ``theta`` (2,); inf when the grid
    has no safe point.
    """
    safe = grid.safe_points
    if len(safe) == 0:
        return math.inf
    theta = np.asarray(theta, dtype=float).reshape(1, 2)
    return float(np.min(np.linalg.norm(safe - theta, axis=1)))


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
        failure): the learning curves of Fig. 3 (:mod:`corl.experiments.door_curves`).
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


def _corl_settings(task, iterations: int):
    """The task's Sec. VIII-B settings with one round and ``iterations`` black-box trials (``max_rl_trials``)."""
    preset = task.method_settings()
    return replace(preset, corl=replace(preset.corl, max_rounds=1, max_rl_trials=iterations))


def true_return(outcome) -> float:
    """R of a successful door Outcome from the true mean force (``info["force_mean"]``), no sensor error."""
    from corl.tasks.door.task import return_of_force

    return return_of_force(outcome.info["force_mean"])


def run_corl(method: str, seed: int, iterations: int, *, task=None) -> DoorRun:
    """One round of Algorithm 1 (motion optimization, then ``iterations`` black-box trials)."""
    from corl.experiments.methods import make_method

    if method not in CORL_METHODS:
        raise InputError(f"unknown CORL method '{method}' for the door; choose one of {', '.join(CORL_METHODS)}")
    t0 = time.perf_counter()
    task = task or _door_task({})
    learner = make_method(method, task, seed=seed, settings=_corl_settings(task, iterations))
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


def run_one(method: str, seed: int, iterations: int, dmp_iterations: int = 150,
            settings: dict | None = None) -> DoorRun:
    """One run of a Fig. 3 row (``method`` in :data:`DOOR_METHODS`) in this process's DoorTask."""
    task = _door_task(settings or {})
    if method == "DMP+PoWER":
        from corl.experiments.door_dmp import run_dmp_power

        return run_dmp_power(seed, dmp_iterations, task=task)
    return run_corl(method, seed, iterations, task=task)


# -- the sweep and the table -----------------------------------------------------------------------
@dataclass(frozen=True)
class DoorBench:
    """Runs, the safe regions they were measured against (by anchor key) and the table rows."""

    runs: list[DoorRun]
    regions: dict[str, SafeRegion]
    table: dict[str, dict]
    curves: dict[str, dict]  # failures and best R over trials (:func:`corl.experiments.door_curves.trial_curves`)


def door_sweep(methods, seeds: int, iterations: int = 100, *, out: str | Path | None = None,
               dmp_iterations: int = 150, grid: tuple[int, int] = (25, 15), jobs: int = 2,
               backend: str = "loky", address: str | None = None, progress: Progress | None = None,
               force_noise: float = 0.0) -> DoorBench:
    """Every method from seeds ``0 .. seeds - 1``, then the safe regions and the table.

    ``force_noise`` (N) adds a seeded error to the force measurement behind R (``DoorTask``), so
    that seeds differ as they would on a robot; S, and so the safe region, stays exact.

    ``jobs``, ``backend`` and ``address`` say where the runs and the safe-region grids go (local
    processes, a Ray or a Dask cluster: :func:`corl.experiments.backends.cluster`, opened once).

    The safe region of a run is realised from that run's anchor (CORL: ``w*`` after motion
    optimization, the same for every seed; DMP+PoWER: the demonstration); each distinct anchor's
    grid is computed once and cached in ``out``.
    """
    from corl.experiments.backends import check_backend, cluster, run_unordered

    methods = list(methods)
    check_backend(backend, address)
    unknown = [m for m in methods if m not in DOOR_METHODS]
    if unknown:
        raise InputError(f"unknown door method(s) {', '.join(unknown)}; choose from {', '.join(DOOR_METHODS)}")
    if seeds < 1 or iterations < 1 or dmp_iterations < 1:
        raise InputError("seeds, iterations and dmp_iterations must be at least 1")
    task = _door_task({})
    settings = _task_settings(task)
    def seeded(s: int) -> dict:  # each seed its own measurement error; exact without noise
        return {**settings, "force_noise": float(force_noise), "seed": s} if force_noise > 0 else settings

    jobs_list = [(m, s, iterations, dmp_iterations, seeded(s)) for m in methods for s in range(seeds)]
    runs = []
    regions: dict[str, SafeRegion] = {}
    with cluster(backend, jobs, address):
        for _, r in run_unordered(run_one, jobs_list, jobs=jobs, backend=backend):
            runs.append(r)
            if progress is not None:
                progress("runs", len(runs), len(jobs_list), f"{r.method} seed {r.seed}: {r.failures}/{r.trials} failed",
                         run=r)
        order = {m: k for k, m in enumerate(methods)}
        runs.sort(key=lambda r: (order[r.method], r.seed))
        for r in runs:
            digest = _digest(r.anchor)
            if digest not in regions:
                anchor_task = _door_task({**settings, "contact_times": r.anchor_times})
                regions[digest] = safe_region(anchor_task, *grid, anchor=r.anchor, cache=out, jobs=jobs,
                                              backend=backend, progress=progress)
    from corl.experiments.door_curves import trial_curves

    budgets = {m: dmp_iterations if m == "DMP+PoWER" else iterations for m in methods}
    return DoorBench(runs, regions, aggregate(runs, regions, methods), trial_curves(runs, methods, budgets))


def _max_distance(run: DoorRun, region: SafeRegion) -> float:
    return max((distance_to_safe(t, region) for t in run.failed_thetas), default=0.0)


def _mean_std(values) -> tuple[float, float]:
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return (float(v.mean()), float(v.std())) if v.size else (math.nan, math.nan)


def aggregate(runs: list[DoorRun], regions: dict[str, SafeRegion], methods) -> dict[str, dict]:
    """Per-method rows of ``door.json``: mean and population std over seeds.

    A NaN (``first_return`` of a run whose first trial failed) is left out of its mean; a row
    without any finite value reads None.
    """
    table = {}
    for m in methods:
        rs = [r for r in runs if r.method == m]
        if not rs:
            continue
        region = {id(r): regions[_digest(r.anchor)] for r in rs}
        rows = {
            "highest_return": [r.highest_return for r in rs],
            "failure_rate": [r.failures / r.trials if r.trials else 0.0 for r in rs],
            "max_dist": [_max_distance(r, region[id(r)]) for r in rs],
            "final_return": [r.final_return for r in rs],
            "failures": [r.failures for r in rs],
            "start_return": [r.start_return for r in rs],
            "first_return": [r.first_return for r in rs],
        }
        entry: dict = {"seeds": len(rs)}
        for name, values in rows.items():
            entry[f"{name}_mean"], entry[f"{name}_std"] = _mean_std(values)
        entry.update({
            "trials_mean": float(np.mean([r.trials for r in rs])),
            "unrealisable_total": int(sum(r.unrealisable for r in rs)),
            "rollouts_mean": float(np.mean([r.rollouts for r in rs])),
            "seconds": float(sum(r.seconds for r in rs)),
            "safe_region": sorted({region[id(r)].key for r in rs}),
            "per_seed": [{"seed": r.seed, "highest_return": r.highest_return, "final_return": r.final_return,
                          "failures": r.failures,
                          "trials": r.trials, "max_dist": _max_distance(r, region[id(r)]),
                          "best_theta": None if r.best_theta is None else r.best_theta.tolist()} for r in rs],
            "paper": dict(zip(("highest_return_mean", "highest_return_std", "failure_rate_mean", "failure_rate_std",
                               "max_dist_mean", "max_dist_std"), PAPER_FIG3.get(m, (None,) * 6))),
        })
        table[m] = _json_safe(entry)
    return table


def _json_safe(value):
    """NaN and inf become None (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_json_safe(v) for v in value]
    return value
