"""``corl report``: one self-contained HTML page per stored run.

A page needs no file beside it and no network: figures are base64 PNG ``data:`` URIs, the video a
base64 MP4 ``data:`` URI, the style sheet is inline. It holds the run's configuration, the library
versions recorded with it, learning curves (J and the return over trials), the return map with the
GP classifier's boundary (Fig. 2c), the table of trials and, for tasks that render, a video of the
demonstration beside the learned motion.

The learner is rebuilt by replaying the stored trials (:meth:`corl.session.StoredRun.open`) into a
fresh learner on the task named on the command line (``corl report --task SPEC``); nothing named
in the store is ever imported. Without ``--task``, or when the replay is impossible (a run of
another task, software that changed so the replay diverges), the page is still written from the
stored trials alone, and says what is missing and why.

Glossary
--------
d       : number of stored trials of a run
J       : analytic cost of a trial's w (Eq. 7), from the replayed learner or ``task.cost_residuals``
R       : the measured return of a trial (None for failures and the pending trial)
"""

from __future__ import annotations

import base64
import json
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from corl.errors import CorlError, InputError
from corl.mujoco.video import RENDERING_HINT
from corl.store import RunInfo, RunStore, StoreError, TrialRecord
from corl.store.files import write_text_atomically

__all__ = ["RunReport", "collect_report", "write_reports", "data_uri", "VIDEO_NAMES"]

VIDEO_NAMES = ("demo_vs_learned.mp4", "demo_vs_learned.gif")  # what `corl run` writes beside its store
_MIME = {".png": "image/png", ".mp4": "video/mp4", ".gif": "image/gif"}


@dataclass
class RunReport:
    """Everything one page shows; figures and the video are already encoded as ``data:`` URIs.

    ``J``: (d,) analytic cost of every trial (NaN when the task could not be loaded);
    ``figures``: further figures as (heading, caption, data URI); ``notes``: what could not be shown and why.
    """

    info: RunInfo
    store_path: Path
    records: list[TrialRecord]
    J: np.ndarray
    best_index: int | None  # the successful trial with the highest return
    learned_index: int | None = None  # the trial of the learner's result (w*, theta*), when replayed
    theta_labels: tuple[str, ...] = ()
    curves: tuple[str, str] | None = None  # (caption, data URI) of J and R over trials
    figures: list[tuple[str, str, str]] = field(default_factory=list)
    return_map: tuple[str, str] | None = None  # (caption, data URI)
    video: tuple[str, str, str] | None = None  # (mime, data URI, where it came from)
    notes: list[str] = field(default_factory=list)
    replayed: bool = False


def data_uri(path: str | Path) -> str:
    """``data:<mime>;base64,...`` of a PNG, MP4 or GIF file."""
    path = Path(path)
    mime = _MIME.get(path.suffix.lower())
    if mime is None:
        raise InputError(f"cannot embed {path.name}: only {', '.join(_MIME)} files are embedded")
    return f"data:{mime};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


# -- rebuilding the run ------------------------------------------------------------------------
def _load_and_replay(db: RunStore, info: RunInfo, notes: list[str], log: Callable[[str], None],
                     task_spec: str | None):
    """(task, learner) of the run, either None with a note saying why; the task comes from ``task_spec``."""
    from corl.session import StoredRun
    from corl.tasks.registry import load_task

    if task_spec is None:
        notes.append("No task was named (corl report --task SPEC), so J, the motion-optimization curve, the "
                      "return map and a rendered video are missing; the trials below come from the store alone.")
        return None, None
    task = load_task(task_spec, seed=int(info.seed or 0))  # a task named but not loadable: InputError
    if task.name != info.task:
        notes.append(f"The task given ('{task_spec}', named '{task.name}') is not this run's task '{info.task}', "
                     "so J, the return map and a rendered video are missing.")
        return None, None
    if info.n_trials:
        log(f"run {info.id}: replaying {info.n_trials} trials of {info.method} on {info.task}")
    try:
        learner = StoredRun.open(db, task, info.id).learner
    except CorlError as exc:
        notes.append(f"The learner could not be rebuilt by replaying the run ({exc}); the return map "
                     "is missing, the trials and J below come from the store and the task.")
        return task, None
    return task, learner


def _costs(task, learner, records: list[TrialRecord]) -> np.ndarray:
    """J (d,) of every trial: the learner's record where it has one, else ``J(w)`` from the task."""
    from corl.learner import cost_of

    known = dict(getattr(learner, "J_history", ()) or ())
    J = np.full(len(records), np.nan)
    for i, record in enumerate(records):
        if record.index in known:
            J[i] = known[record.index]
        elif task is not None:
            J[i] = cost_of(task, record.proposal.w)
    return J


def _learned_index(learner, records: list[TrialRecord]) -> int | None:
    """Position of the last successful trial whose w is the learner's result ``best.w``, or None."""
    best = getattr(learner, "best", None)
    if best is None:
        return None
    hits = [i for i, r in enumerate(records) if r.outcome is not None and r.outcome.success
            and r.proposal.w.shape == np.shape(best.w) and np.array_equal(r.proposal.w, best.w)]
    return hits[-1] if hits else None


def _best_index(records: list[TrialRecord]) -> int | None:
    """Position of the successful trial with the highest return (the first on ties), or None."""
    ok = [(r.outcome.return_, -i) for i, r in enumerate(records)
          if r.outcome is not None and r.outcome.success and r.outcome.return_ is not None]
    return -max(ok)[1] if ok else None


# -- figures ------------------------------------------------------------------------------------
def _figures(report: RunReport, task, learner, folder: Path) -> None:
    """Learning curves and the return map, as data URIs in ``report``."""
    from corl.experiments.figures import plot_learning_curve, plot_return_map, plot_trials

    if any(r.outcome is not None for r in report.records):
        report.curves = ("J(w) of every trial (top; values below 1e-12 are drawn at 1e-12) and its return "
                         "(bottom, with the best observed reading so far); failures in red, dotted lines separate "
                         "the rounds of Algorithm 1.",
                         data_uri(plot_trials(report.records, report.J, folder / "trials.png")))
    if learner is None:
        return
    if getattr(learner, "J_history", None) and getattr(learner, "optimizers", None) is not None:
        report.figures.append(("Motion optimization (Fig. 2b)", "J(w) of the rollouts of the optimization "
                               "steps; the red dashed lines mark step 2 (RL over theta).",
                               data_uri(plot_learning_curve(learner, folder / "learning_curve.png"))))
    if not getattr(learner, "optimizers", None):
        report.notes.append("No return map: this run has no black-box step over theta "
                            "(a method over w, or Algorithm 1 stopped before step 2).")
        return
    if task.theta_bounds.dim > 2:
        report.notes.append(f"No return map: theta has {task.theta_bounds.dim} dimensions, a map shows 1 or 2.")
        return
    try:
        path = plot_return_map(learner, folder / "return_map.png", labels=report.theta_labels)
    except (ValueError, CorlError) as exc:
        report.notes.append(f"No return map: {exc}.")
        return
    where = ("green band: where the success classifier predicts success (p > 0.5)" if task.theta_bounds.dim == 1
             else "red line: the success classifier's boundary p = 0.5")
    report.return_map = (f"GP mean of R over theta from the last round's black-box data; {where}; star: the "
                         "learner's best theta.", data_uri(path))


def _existing_video(store_path: Path, run_id: int, n_runs: int) -> Path | None:
    """The video `corl run` wrote beside the store for this run, if any.

    ``summary.json`` beside the store names the run its video shows; without it, a video is taken
    to be this run's only when the store holds a single run.
    """
    folder = store_path.parent
    summary = folder / "summary.json"
    if summary.is_file():
        try:
            payload = json.loads(summary.read_text())
        except (OSError, ValueError):
            payload = {}
        video = (payload.get("files") or {}).get("video")
        if payload.get("run_id") == run_id and video:
            path = folder / Path(video).name  # `corl run` writes it beside summary.json
            return path if path.is_file() else None
        if payload.get("run_id") is not None:
            return None
    if n_runs == 1:
        return next((folder / name for name in VIDEO_NAMES if (folder / name).is_file()), None)
    return None


def _video(report: RunReport, task, learner, folder: Path, n_runs: int) -> None:
    """Embed the run's video: the one beside the store, else a fresh rendering."""
    render = getattr(task, "render_comparison", None)
    existing = _existing_video(report.store_path, report.info.id, n_runs)
    if existing is not None:
        report.video = (_MIME[existing.suffix.lower()], data_uri(existing), f"{existing.name} beside the store")
        return
    if render is None or not report.records:
        return
    best = getattr(learner, "best", None)
    if best is not None:
        w_best = best.w
    elif report.best_index is not None:
        w_best = report.records[report.best_index].proposal.w
    else:
        report.notes.append("No video: the run has no successful trial to show.")
        return
    try:
        path = Path(render(report.records[0].proposal.w, w_best, folder / "demo_vs_learned.mp4"))
    except Exception as exc:  # no OpenGL on this machine: the rest of the page stands without it
        report.notes.append(f"No video ({type(exc).__name__}: {exc}). {RENDERING_HINT}, or pass --no-video.")
        return
    report.video = (_MIME[path.suffix.lower()], data_uri(path), "rendered for this report")


def collect_report(db: RunStore, info: RunInfo, *, video: bool = True, n_runs: int = 1,
                   log: Callable[[str], None] = lambda message: None, task_spec: str | None = None) -> RunReport:
    """Everything the page of run ``info`` shows: trials, J, figures, video and notes.

    ``task_spec`` names the task (as on the command line); without it the page shows the stored data only.
    """
    records = db.trials(info.id)
    notes: list[str] = []
    task, learner = _load_and_replay(db, info, notes, log, task_spec)
    labels = tuple(getattr(task, "theta_labels", ()) or ())
    dim = records[0].proposal.theta.shape[0] if records else 0
    if len(labels) != dim:
        labels = tuple(f"theta {k + 1}" for k in range(dim))
    report = RunReport(info=info, store_path=Path(db.path), records=records, J=_costs(task, learner, records),
                       best_index=_best_index(records), learned_index=_learned_index(learner, records),
                       theta_labels=labels, notes=notes,
                       replayed=learner is not None)
    _draw(report, task, learner, video=video, n_runs=n_runs)
    return report


def _draw(report: RunReport, task, learner, *, video: bool, n_runs: int) -> None:
    """Figures and video, drawn in a temporary folder (removed after) and embedded in ``report``.

    A disk that is full there is an :class:`InputError`, not a half-drawn page."""
    try:
        with tempfile.TemporaryDirectory(prefix="corl-report-") as tmp:
            _figures(report, task, learner, Path(tmp))
            if video:
                _video(report, task, learner, Path(tmp), n_runs)
    except OSError as exc:
        raise InputError(f"cannot draw the figures of run {report.info.id} in the temporary folder "
                         f"{tempfile.gettempdir()}: {exc.strerror or exc}; free disk space there (or point TMPDIR to "
                         "a folder with space)") from None


def write_reports(store: str | Path, out: str | Path, *, run_id: int | None = None, video: bool = True,
                  log: Callable[[str], None] = lambda message: None, task_spec: str | None = None) -> list[Path]:
    """Write ``OUT/run_<id>.html`` for every run of the store (or only ``run_id``).

    ``task_spec`` (``corl report --task``) names the task whose learner is rebuilt by replay; without
    it the pages show the stored data alone, and ``log`` says what they leave out.
    With more than one page, ``OUT/index.html`` lists them. Returns the paths written, index last.
    Raises :class:`StoreError` for a missing or damaged store, an unknown run or an empty store, and
    :class:`InputError` for a ``task_spec`` that cannot be loaded.
    """
    from corl.experiments.html.page import render_index, render_page

    store, out = Path(store), Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out} is a file; give a folder for the report pages")
    with RunStore(store, readonly=True, create=False) as db:
        every_run = db.runs()
        infos = every_run if run_id is None else [db.run(run_id)]
        if not infos:
            raise StoreError(f"{store} holds no run yet, so there is nothing to report; "
                             "start one with 'corl run' or 'corl ask'")
        if task_spec is None:
            log("no --task given: the pages show the stored trials only, without J, the motion-optimization "
                "curve, the return map or a rendered video; add --task SPEC (as given to 'corl run') for them")
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot create the report folder {out}: {exc.strerror}; choose another --out") from None
        written = []
        for info in infos:
            report = collect_report(db, info, video=video, n_runs=len(every_run), log=log, task_spec=task_spec)
            written.append(_write_text(out / f"run_{info.id}.html", render_page(report)))
            log(f"run {info.id}: wrote {written[-1]}")
    if len(written) > 1:
        written.append(_write_text(out / "index.html", render_index(infos, store)))
    return written


def _write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file, removed on failure: never half a page."""
    return write_text_atomically(path, text, hint="check that --out is writable and has free space")
