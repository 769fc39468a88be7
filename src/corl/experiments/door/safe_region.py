"""The ground truth of the door study: the safe region over theta, and a failure's distance to it.

Glossary
--------
theta        : (2,) grasp shift along the handle (m) and finger width (m), the door's theta
safe region  : the thetas whose realisation (Eq. 18 from an anchor trajectory) opens the door,
               measured on a grid over ``task.theta_bounds`` (:func:`safe_region`)
anchor       : the trajectory a theta is realised from (:mod:`corl.experiments.door.runs`)
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from corl.errors import InputError
from corl.experiments.door.runs import Progress, digest, door_task, task_settings
from corl.experiments.sweep import sweep_task
from corl.versions import library_versions

__all__ = ["SafeRegion", "safe_region", "distance_to_safe"]


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
    if n1 < 2 or n2 < 2:
        raise InputError(f"the safe-region grid needs at least 2 x 2 points, got {n1} x {n2}")
    settings = task_settings(task)
    anchor = np.asarray(task.demonstration().w if anchor is None else anchor, dtype=float)
    bounds = task.theta_bounds
    theta1 = np.linspace(bounds.lower[0], bounds.upper[0], n1)
    theta2 = np.linspace(bounds.lower[1], bounds.upper[1], n2)
    key_source = {"task": settings, "lower": bounds.lower.tolist(), "upper": bounds.upper.tolist(),
                  "grid": [n1, n2], "anchor": digest(anchor), "versions": library_versions()}
    key = hashlib.sha256(json.dumps(key_source, sort_keys=True).encode()).hexdigest()[:16]
    path = None if cache is None else Path(cache) / f"door_safe_region_{key}.npz"
    if path is not None and path.exists():
        with np.load(path) as f:
            return SafeRegion(f["theta1"], f["theta2"], f["success"], f["realised"], key)

    def tick(done: int, total: int, safe: int) -> None:
        if progress is not None:
            progress("safe region", done, total, f"{safe} safe so far")

    theta_anchor = np.asarray(task.demonstration().theta, dtype=float)  # step 1 keeps theta: w* realises theta0
    grid = sweep_task(partial(door_task, settings), (n1, n2), anchor=anchor, theta_anchor=theta_anchor,
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
