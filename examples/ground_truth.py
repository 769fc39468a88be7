"""A scene's ground truth for the example context families: the best return reachable there.

The return of a motion depends on theta and on the motion that realises it; corl runs, at a fixed
theta, the motion of its step 1: Eq. 8 (J under h(., theta) = 0) solved to convergence. So the best
return in a scene is the maximum, over theta, of the return of that motion. :func:`best_return`
finds it on a grid over ``theta_bounds`` (serpentine, each point's motion solved from its
neighbour's: continuation) refined by a finer grid around the coarse best, and keeps the answer in
``~/.cache/corl-examples`` (``CORL_EXAMPLES_CACHE`` overrides), keyed by the task's name, its
scene, the grids and a hash of the task's source file: a changed example computes afresh.
"""

from __future__ import annotations

import hashlib
import inspect
import json
import os
from pathlib import Path

import numpy as np

from corl.realise import feasible, motion_problem
from corl.trajectory import solve

__all__ = ["motion_at", "returns_on_grid", "best_return"]


def _solver(task):
    preset = getattr(task, "method_settings", None)
    if callable(preset):
        return preset().corl.solver
    from corl.settings import CORLConfig

    return CORLConfig().solver


def motion_at(task, theta, w_start):
    """The motion corl runs at ``theta`` (m,): Eq. 8 solved from ``w_start`` (n,); None when it does not
    reach h = 0."""
    solver = _solver(task)
    result = solve(motion_problem(task, np.asarray(theta, dtype=float)), w_start, config=solver)
    return result.w if feasible(result, solver) else None


def returns_on_grid(task, axes, w_anchor) -> tuple[np.ndarray, np.ndarray]:
    """Every theta of the grid ``axes`` (one 1-D array per theta coordinate, 1 or 2 of them): points
    (K, m) and the return of the motion at each (K,), NaN for a failure or no motion. A point whose
    motion does not follow from its neighbour's is solved from ``w_anchor`` (the demonstration)."""
    axes = [np.asarray(a, dtype=float) for a in axes]
    rows = [(a,) for a in axes[0]] if len(axes) == 1 else [
        tuple(p) for i, a in enumerate(axes[0]) for p in
        ((a, b) for b in (axes[1] if i % 2 == 0 else axes[1][::-1]))]
    points, returns, w = [], [], w_anchor
    for theta in rows:
        w_new = motion_at(task, theta, w)
        if w_new is None and w is not w_anchor:
            w_new = motion_at(task, theta, w_anchor)
        outcome = None if w_new is None else task.rollout(w_new)
        points.append(theta)
        returns.append(float(outcome.return_) if outcome is not None and outcome.success else np.nan)
        w = w_anchor if w_new is None else w_new
    return np.array(points), np.array(returns)


def _cache_file(task, coarse, fine) -> Path:
    source = Path(inspect.getfile(type(task))).read_bytes()
    key = json.dumps([task.name, np.asarray(task.context, dtype=float).tolist(), list(coarse), fine,
                      hashlib.sha256(source).hexdigest()[:16]])
    root = Path(os.environ.get("CORL_EXAMPLES_CACHE", Path.home() / ".cache" / "corl-examples"))
    return root / f"{task.name}-{hashlib.sha256(key.encode()).hexdigest()[:20]}.json"


def best_return(task, w_anchor, coarse, fine: int = 9, *, cache: bool = True) -> dict:
    """The best return over theta in ``task``'s scene: a grid of ``coarse`` (one count per theta
    coordinate) points over theta_bounds, then ``fine`` points per coordinate over one coarse step
    either side of its best. Returns {"best_return", "theta", "points", "successes"}; raises
    ValueError when no grid point succeeds."""
    path = _cache_file(task, coarse, fine) if cache else None
    if path is not None and path.exists():
        return json.loads(path.read_text())
    lo, hi = task.theta_bounds.lower, task.theta_bounds.upper
    axes = [np.linspace(a, b, g) for a, b, g in zip(lo, hi, coarse)]
    points, returns = returns_on_grid(task, axes, w_anchor)
    if np.all(np.isnan(returns)):
        raise ValueError(f"no theta of the {'x'.join(map(str, coarse))} grid succeeds in scene "
                         f"{np.asarray(task.context).tolist()}")
    centre = points[int(np.nanargmax(returns))]
    step = (hi - lo) / (np.asarray(coarse) - 1)
    fine_axes = [np.linspace(max(a - s, b), min(a + s, c), fine) for a, s, b, c in zip(centre, step, lo, hi)]
    fine_points, fine_returns = returns_on_grid(task, fine_axes, w_anchor)
    points, returns = np.vstack([points, fine_points]), np.concatenate([returns, fine_returns])
    k = int(np.nanargmax(returns))
    answer = {"best_return": float(returns[k]), "theta": points[k].tolist(), "points": int(len(points)),
              "successes": int(np.sum(~np.isnan(returns)))}
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(answer))
    return answer
