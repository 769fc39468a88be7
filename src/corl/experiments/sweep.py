"""The ground truth of a simulated task over theta: success region and return on a grid (``corl sweep``).

Every theta of a grid over ``task.theta_bounds`` is realised from an anchor trajectory exactly as
the learner does it (Eq. 18, :func:`corl.realise.realise`: the task's projection metric, the
continuation, the solver settings of the task's CORLConfig), rolled out, and its S and R recorded.
The door benchmark's safe region (Fig. 3's "max distance") is this sweep from the run's ``w*``.

Glossary
--------
grid      : points per theta coordinate, (m,) ints; the grid is their Cartesian product (row-major)
anchor    : (n,) the trajectory thetas are realised from (default the demonstration's ``w0``)
success   : grid-shaped bool, the realised theta succeeded; realised : Eq. 18 found a feasible w
returns   : grid-shaped float, R of the rollout (NaN where it failed or was not rolled out)
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from corl.errors import InputError, RolloutError
from corl.experiments.figures import plot_sweep
from corl.problem import Outcome
from corl.store.files import write_atomically, write_text_atomically

__all__ = ["Sweep", "TaskSpec", "parse_grid", "check_grid", "evaluate_points", "sweep_task", "write_sweep",
           "sweep_command", "write_raw_parameters", "MAX_SWEEP_POINTS"]

MAX_SWEEP_POINTS = 1_000_000  # each point is a realisation and a rollout: 10^6 synthetic ones take ~20 min on
# one core (~1 ms each), a simulator's far longer; the arrays and the CSV (~25 MB) stay small

Progress = Callable[[int, int, int], None]  # (points done, total, successes so far)

_BUILT: dict[tuple, object] = {}  # one task per worker process and spec (a MuJoCo scene loads once)


@dataclass(frozen=True)
class TaskSpec:
    """A picklable task builder for workers: ``corl run``'s task argument and seed (built once per process);
    ``context`` (k floats): the task in that scene (``with_context(c)``, checked), else its own."""

    spec: str
    seed: int = 0
    context: tuple | None = None

    def __call__(self):
        key = (self.spec, self.seed, self.context)
        if key not in _BUILT:
            from corl.tasks.registry import load_task

            task = load_task(self.spec, seed=self.seed)
            if self.context is not None:
                from corl.contexts.skill import scene_of

                task = scene_of(task, np.array(self.context, dtype=float))
            _BUILT[key] = task
        return _BUILT[key]


@dataclass(frozen=True)
class Sweep:
    """Success and return of a grid over theta.

    Attributes
    ----------
    axes : m arrays, the grid of each theta coordinate.
    success, realised : bool arrays of shape ``grid``; returns : float array of shape ``grid``.
    anchor_theta : (m,) the theta the anchor realises.
    """

    axes: tuple[np.ndarray, ...]
    success: np.ndarray
    realised: np.ndarray
    returns: np.ndarray
    anchor_theta: np.ndarray

    @property
    def points(self) -> np.ndarray:
        """(N, m) every grid point, row-major like ``success.ravel()``."""
        mesh = np.meshgrid(*self.axes, indexing="ij")
        return np.column_stack([g.ravel() for g in mesh])

    @property
    def safe_points(self) -> np.ndarray:
        """(k, m) the successful grid points."""
        return self.points[self.success.ravel()]


def parse_grid(text: str, dim: int) -> tuple[int, ...]:
    """``"25,15"`` or ``"25x15"`` (or one number for every coordinate) -> points per coordinate."""
    parts = [p for p in text.lower().replace("x", ",").split(",") if p.strip()]
    try:
        sizes = tuple(int(p) for p in parts)
    except ValueError:
        raise InputError(f"--grid must be points per theta coordinate like 25,15, got {text!r}") from None
    if len(sizes) == 1:
        sizes = sizes * dim
    if len(sizes) != dim:
        raise InputError(f"--grid {text!r} gives {len(sizes)} sizes, but theta has {dim} coordinates")
    return check_grid(sizes, dim, what=f"--grid {text!r}")


def check_grid(sizes: tuple[int, ...], dim: int, *, what: str) -> tuple[int, ...]:
    """``sizes`` if they give each of theta's ``dim`` coordinates 2 or more points and at most
    :data:`MAX_SWEEP_POINTS` points in all, else :class:`InputError` (before any array is made)."""
    if len(sizes) != dim or min(sizes, default=0) < 2:
        raise InputError(f"{what} needs at least 2 points in each of theta's {dim} coordinates")
    total = math.prod(sizes)
    if total > MAX_SWEEP_POINTS:
        raise InputError(f"{what} makes {total} grid points; a sweep takes at most {MAX_SWEEP_POINTS} "
                         "(every point is a rollout): give fewer points per coordinate")
    return sizes


def _solver(task):
    """The solver settings the learner would use on ``task`` (its CORLConfig's)."""
    from corl.settings import CORLConfig

    preset = getattr(task, "method_settings", None)  # corl.problem.HasMethodSettings
    corl = preset().corl if callable(preset) else CORLConfig()
    return corl.solver


def evaluate_points(task, anchor, theta_anchor, thetas) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Realise every theta (k, m) from ``anchor`` (n,) with Eq. 18 and roll it out.

    Returns success (k,), realised (k,) and returns (k,) (NaN without a successful rollout).
    """
    from corl.realise import realise

    solver = _solver(task)
    thetas = np.asarray(thetas, dtype=float).reshape(-1, task.theta_bounds.dim)
    success = np.zeros(len(thetas), dtype=bool)
    realised = np.zeros(len(thetas), dtype=bool)
    returns = np.full(len(thetas), np.nan)
    for k, theta in enumerate(thetas):
        result = realise(task, anchor, theta_anchor, theta, solver)
        realised[k] = result.feasible
        if result.feasible:
            outcome = _rollout(task, result.w, theta)
            success[k] = outcome.success
            if outcome.success:
                returns[k] = float(outcome.return_)
    return success, realised, returns


def _rollout(task, w, theta) -> Outcome:
    """``task.rollout(w)``; a rollout that raises (or exits) or returns no Outcome is a :class:`RolloutError`."""
    where = f"the rollout of task '{task.name}' at theta {np.array2string(np.asarray(theta), precision=6)}"
    try:
        outcome = task.rollout(w)
    except (Exception, SystemExit) as exc:  # user code: a sys.exit() there must not end a sweep silently
        raise RolloutError(f"{where} raised {type(exc).__name__}: {exc}; fix the task's rollout (call it in "
                           "Python to see the traceback); nothing was written") from None
    if not isinstance(outcome, Outcome):
        raise RolloutError(f"{where} returned a {type(outcome).__name__}, not a corl.Outcome; fix the task's rollout")
    return outcome


def _chunk(make_task, anchor, theta_anchor, thetas):
    return evaluate_points(make_task(), anchor, theta_anchor, thetas)


def sweep_task(make_task: Callable[[], object], grid, *, anchor=None, theta_anchor=None, jobs: int = 1,
               backend: str = "loky", address: str | None = None, progress: Progress | None = None) -> Sweep:
    """Success and return of every theta of ``grid`` over the task's bounds.

    Parameters
    ----------
    make_task : a picklable callable that builds the task (:class:`TaskSpec`, or a module-level
        function / ``functools.partial``); workers build their own copy.
    grid : points per theta coordinate, (m,) ints (:func:`parse_grid`).
    anchor, theta_anchor : (n,) and (m,) the trajectory thetas are realised from and the theta it
        realises; default the demonstration's ``(w0, theta0)``.
    jobs, backend, address : parallel workers and where they run (:mod:`corl.experiments.backends`);
        ``jobs=1`` runs in this process.
    progress : ``(done, total, successes)`` as chunks finish.
    """
    from joblib import effective_n_jobs

    from corl.experiments.backends import check_backend, cluster, run_unordered

    task = make_task()
    bounds = task.theta_bounds
    grid = tuple(int(g) for g in grid)
    check_grid(grid, bounds.dim, what=f"the grid {grid}")
    if anchor is None or theta_anchor is None:
        demo = task.demonstration()
        anchor = demo.w if anchor is None else anchor
        theta_anchor = demo.theta if theta_anchor is None else theta_anchor
    anchor = np.asarray(anchor, dtype=float)
    theta_anchor = np.asarray(theta_anchor, dtype=float).reshape(bounds.dim)
    axes = tuple(np.linspace(lo, hi, g) for lo, hi, g in zip(bounds.lower, bounds.upper, grid))
    mesh = np.meshgrid(*axes, indexing="ij")
    points = np.column_stack([g.ravel() for g in mesh])
    success = np.zeros(len(points), dtype=bool)
    realised = np.zeros(len(points), dtype=bool)
    returns = np.full(len(points), np.nan)
    if jobs == 1 and backend == "loky":
        success[:], realised[:], returns[:] = evaluate_points(task, anchor, theta_anchor, points)
        if progress is not None:
            progress(len(points), len(points), int(success.sum()))
    else:
        check_backend(backend, address)
        done = 0
        with cluster(backend, jobs, address):
            n_chunks = min(len(points), 4 * max(1, effective_n_jobs(jobs)))
            chunks = [np.arange(j, len(points), n_chunks) for j in range(n_chunks)]  # interleaved: even work
            arguments = [(make_task, anchor, theta_anchor, points[idx]) for idx in chunks]
            for k, (s, r, R) in run_unordered(_chunk, arguments, jobs=jobs, backend=backend):
                success[chunks[k]], realised[chunks[k]], returns[chunks[k]] = s, r, R  # by grid index
                done += len(chunks[k])
                if progress is not None:
                    progress(done, len(points), int(success.sum()))
    return Sweep(axes, success.reshape(grid), realised.reshape(grid), returns.reshape(grid), theta_anchor)


_HINT = "free disk space or choose another --out"  # what to do when a file of the sweep cannot be written


def write_sweep(sweep: Sweep, out: str | Path, *, labels=None, title: str = "", meta: dict | None = None) -> dict[str, str]:
    """``sweep.csv`` (one row per grid point), ``sweep.json`` and, for m <= 2, ``sweep.png`` (the map).

    Each file is written whole or not at all (:func:`corl.store.files.write_atomically`); a folder
    or file that cannot be written (a full disk, a read-only place) is an :class:`InputError`.
    Returns {kind: path}; the map of a theta with more than 2 coordinates is skipped (``png_skipped``).
    ``meta`` (e.g. ``{"context": [...]}``) goes into ``sweep.json`` first.
    """
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create the sweep folder {out}: {exc.strerror}; choose another --out") from None
    m = len(sweep.axes)
    labels = tuple(labels) if labels is not None and len(labels) == m else tuple(f"theta{k + 1}" for k in range(m))
    files = {"csv": str(write_atomically(out / "sweep.csv", lambda tmp: _write_csv(tmp, sweep), hint=_HINT))}
    payload = {**(meta or {}), **_summary(sweep, labels), "csv": files["csv"]}
    files["json"] = str(write_text_atomically(out / "sweep.json", json.dumps(payload, indent=2) + "\n", hint=_HINT))
    if m > 2:
        files["png_skipped"] = f"no map for a theta with {m} coordinates (the CSV has every point)"
        return files
    draw = lambda tmp: plot_sweep(sweep, tmp, labels=labels, title=title)  # noqa: E731
    files["png"] = str(write_atomically(out / "sweep.png", draw, hint=_HINT))
    return files


def _write_csv(path: Path, sweep: Sweep) -> None:
    m = len(sweep.axes)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow([f"theta{k + 1}" for k in range(m)] + ["realised", "success", "return"])
        for p, r, s, R in zip(sweep.points, sweep.realised.ravel(), sweep.success.ravel(), sweep.returns.ravel()):
            writer.writerow([f"{v:.10g}" for v in p] + [int(r), int(s), "" if np.isnan(R) else f"{R:.10g}"])


def _summary(sweep: Sweep, labels: tuple[str, ...]) -> dict:
    """What ``sweep.json`` holds besides the CSV's path: the grid, counts and the best successful point."""
    points, best = sweep.points, None
    if sweep.success.any():
        k = int(np.nanargmax(np.where(sweep.success.ravel(), sweep.returns.ravel(), np.nan)))
        best = {"theta": points[k].tolist(), "return": float(sweep.returns.ravel()[k])}
    return {"labels": list(labels), "grid": list(sweep.success.shape), "axes": [a.tolist() for a in sweep.axes],
            "anchor_theta": sweep.anchor_theta.tolist(), "points": int(points.shape[0]),
            "successes": int(sweep.success.sum()), "unrealised": int((~sweep.realised).sum()), "best": best}


def sweep_command(task: str, grid: str, out, *, seed: int = 0, jobs: int = 1, backend: str = "loky",
                  address: str | None = None, tracker=None, context=None) -> dict:
    """``corl sweep``: build the task, sweep the grid from the demonstration, write the files; the JSON payload.
    ``context`` (k,): sweep the task in that scene, from the scene's own demonstration."""
    spec = TaskSpec(task, seed, None if context is None else tuple(float(v) for v in context))
    the_task = spec()
    meta = {} if context is None else {"context": list(spec.context)}
    if context is not None:
        _check_scene_demonstration(the_task, spec.context)
    sizes = parse_grid(grid, the_task.theta_bounds.dim)
    def progress(done, total, ok):
        if tracker is not None:
            tracker.update("grid", done=done, total=total, note=f"{ok} succeed")

    if tracker is not None:
        tracker.add_stage("grid", total=math.prod(sizes))
    result = sweep_task(spec, sizes, jobs=jobs, backend=backend, address=address, progress=progress)
    title = the_task.name + ("" if context is None else f" in context {', '.join(f'{v:g}' for v in spec.context)}")
    files = write_sweep(result, out, labels=getattr(the_task, "theta_labels", None), title=title, meta=meta)
    return {"task": the_task.name, **meta, "grid": list(sizes), "points": int(result.success.size),
            "successes": int(result.success.sum()), "unrealised": int((~result.realised).sum()),
            "best": json.loads(Path(files["json"]).read_text())["best"], "files": files}


def _check_scene_demonstration(scene, context: tuple) -> None:
    """A sweep in a scene starts from the scene's demonstration: one that raises is an :class:`InputError`
    naming the scene (not a traceback from a worker)."""
    from corl.errors import CorlError

    where = ",".join(f"{v:g}" for v in context)
    try:
        scene.demonstration()
    except CorlError as exc:
        raise InputError(f"task '{scene.name}' in context {where}: {exc}") from None
    except Exception as exc:  # the task's own code
        raise InputError(f"task '{scene.name}' in context {where}: demonstration() raised {type(exc).__name__}: "
                         f"{exc}; a sweep in a scene starts from that scene's demonstration: fix it, or sweep "
                         "another --context") from None


def write_raw_parameters(proposal, folder) -> dict:
    """``corl ask --raw``: the parameters w as one labelled row, never mistaken for joint positions.

    Writes ``trial_<i>_raw_parameters.csv`` (a comment line saying what it is, then ``w0..w{n-1}``)
    and ``.npz``; returns what ``corl ask`` prints.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stem = folder / f"trial_{proposal.index:04d}_raw_parameters"
    np.savez(stem.with_suffix(".npz"), w=proposal.w, theta=proposal.theta, raw_parameters=True)
    header = ("# raw parameters w of the policy, not a joint trajectory: never send them to a robot\n"
              + ",".join(f"w{j}" for j in range(proposal.w.shape[0])))
    np.savetxt(stem.with_suffix(".csv"), np.asarray(proposal.w, dtype=float)[None, :], delimiter=",",
               header=header, comments="")
    return {"trial": proposal.index, "step": proposal.step, "round": proposal.round,
            "theta": proposal.theta.tolist(), "raw_parameters": True,
            "csv": str(stem.with_suffix(".csv")), "npz": str(stem.with_suffix(".npz"))}
