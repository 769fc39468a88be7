"""``corl status``, ``corl runs``, ``corl export`` and ``corl report``: what a run store holds, as text,
JSON, a table file or HTML pages."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from corl.arguments import NEW_PATHS
from corl.cli.common import JSON_OUT, QUIET, check_args, fail, open_store, print_json, progress_tracker

__all__ = ["status", "runs", "export", "report"]


def _run_info(r) -> dict:
    """A :class:`corl.store.RunInfo` as JSON (``corl runs --json``, ``corl status --json``)."""
    return {"id": r.id, "task": r.task, "method": r.method, "seed": r.seed, "status": r.status.value,
            "created": r.created, "trials": r.n_trials, "told": r.n_told, "context": r.config.get("context")}


def _scene(r) -> str:
    """A run's scene as ``corl run --context`` takes it (``-0.5,0.25``), ``-`` for a run without contexts."""
    c = r.config.get("context")
    return "-" if c is None else ",".join(f"{float(v):.6g}" for v in c)


def status(store: Path = typer.Option(..., help="run store"),
           run_id: Optional[int] = typer.Option(None, "--run", help="run id (default: latest)"),
           json_out: bool = JSON_OUT) -> None:
    """Show a run: its configuration, trials so far, failures, the learner's best and the best observed reading."""
    from corl.errors import CorlError

    check_args(path=("--store", store))
    try:
        with open_store(store, readonly=True) as db:
            info = db.run(run_id) if run_id is not None else db.latest_run()
            if info is None:
                fail(f"{store} holds no run yet", code=1)
            trials = db.trials(info.id)
            learners, ended = db.best(info.id), db.end(info.id)
    except CorlError as exc:
        fail(str(exc))
    told = [t for t in trials if t.outcome is not None]
    ok = [t for t in told if t.outcome.success]
    observed = max(ok, key=lambda t: t.outcome.return_, default=None)  # the highest reading: not what to deploy
    seen = None if observed is None else {"trial": observed.index, "return": observed.outcome.return_,
                                          "theta": observed.proposal.theta.tolist()}
    if json_out:
        return print_json({**_run_info(info), "trials": len(trials), "told": len(told),
                           "pending": len(trials) - len(told), "failures": len(told) - len(ok),
                           "best": learners, "best_observed": seen, "ended": ended})
    scene = "" if info.config.get("context") is None else f", context {_scene(info)}"
    typer.echo(f"run {info.id}: task {info.task}, method {info.method}, seed {info.seed}{scene}, {info.status.value}")
    typer.echo(f"trials {len(trials)} (told {len(told)}, pending {len(trials) - len(told)}), "
               f"failures {len(told) - len(ok)}")
    if learners is not None:
        std = "" if learners.get("return_std") is None else f" +- {learners['return_std']:.3g}"
        typer.echo(f"learner's best: return {learners['return']:.6g}{std} at trial {learners.get('trial')}, "
                   f"theta {[round(float(v), 6) for v in learners['theta']]}")
    if seen is not None:
        typer.echo(f"best observed: reading {seen['return']:.6g} at trial {seen['trial']}")
    if ended is not None:  # corl run --resume --end-at-error
        typer.echo(f"ended at trial {ended['trial']}, where the task's {ended['member']} raised {ended['error']}")


def runs(store: Path = typer.Option(..., help="run store"), json_out: bool = JSON_OUT) -> None:
    """List a store's runs."""
    from corl.errors import CorlError

    check_args(path=("--store", store))
    try:
        with open_store(store, readonly=True) as db:
            infos = db.runs()
    except CorlError as exc:
        fail(str(exc))
    if json_out:
        return print_json({"runs": [_run_info(r) for r in infos]})
    width = max([12] + [len(r.task) for r in infos])
    typer.echo(f"{'id':>4} {'task':<{width}} {'method':<20} {'seed':>6} {'trials':>7} {'status':<9} {'created':<25} "
               "context")
    for r in infos:
        typer.echo(f"{r.id:>4} {r.task:<{width}} {r.method:<20} {r.seed!s:>6} {r.n_trials:>7} {r.status.value:<9} "
                   f"{r.created:<25} {_scene(r)}")


def export(store: Path = typer.Option(..., help="run store"),
           out: Path = typer.Option(..., help="file to write: .csv or .parquet (w vectors go beside it as .npz)"),
           run_id: Optional[int] = typer.Option(None, "--run", help="run id (default: latest)"),
           all_runs: bool = typer.Option(False, "--all", help="every run of the store in one table, a 'run' column "
                                                             "first (with a run's scene in context_0.. columns)")) -> None:
    """Export a run's trials (or every run's, --all) for analysis; a run in a context gets its scene's columns."""
    from corl.errors import CorlError

    check_args(path=("--store", store), export=("--out", out))
    if all_runs and run_id is not None:
        fail(f"--all exports every run; drop --run {run_id} (or --all to export run {run_id} only)")
    try:
        with open_store(store, readonly=True) as db:
            info = db.run(run_id) if run_id is not None else db.latest_run()
            if info is None:
                fail(f"{store} holds no run yet", code=1)
            table, arrays = db.export([r.id for r in db.runs()] if all_runs else info.id, out)
    except CorlError as exc:
        fail(str(exc))
    typer.echo(f"wrote {table} and {arrays}")


def report(store: Path = typer.Option(..., help="run store"),
           out: Path = typer.Option(..., help="folder for the pages run_<id>.html (and index.html)"),
           run_id: Optional[int] = typer.Option(None, "--run", help="run id (default: every run)"),
           video: bool = typer.Option(True, "--video/--no-video", help="embed the video for tasks that render"),
           task: Optional[str] = typer.Option(None, help="the runs' task, as given to 'corl run' (never read "
                                                        "from the store); without it the pages show stored data only"),
           quiet: bool = QUIET, json_out: bool = JSON_OUT) -> None:
    """One self-contained HTML page per run: configuration, versions, curves, return map, trials, video."""
    from corl.errors import CorlError
    from corl.experiments.html import write_reports

    check_args(path=("--store", store), task=("--task", task), folder=("--out", out))
    NEW_PATHS.track(out)
    if video and task is not None:  # before the task imports MuJoCo: an offscreen backend that works
        from corl.mujoco.video import ensure_rendering

        ensure_rendering()  # when none does, the page says why it has no video
    with progress_tracker("report", quiet=quiet, log=True, json_out=json_out) as tracker:  # messages only
        try:
            pages = write_reports(store, out, run_id=run_id, video=video, log=tracker.message, task_spec=task)
        except CorlError as exc:
            fail(str(exc))
    if json_out:
        return print_json({"store": str(store), "pages": [str(page) for page in pages]})
    for page in pages:
        typer.echo(str(page))
