"""``corl run``, ``corl ask`` and ``corl tell``: a learning run, in the simulator or trial by trial on a
robot, every trial committed to the run store (:mod:`corl.session`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from corl.arguments import NEW_PATHS, latest_run
from corl.cli.common import JSON_OUT, LOG, QUIET, check_args, fail, open_store, print_json, progress_tracker, write_json

__all__ = ["run", "ask", "tell"]


def run(
    task: str = typer.Argument(..., help="'synthetic', or an import path 'package.module:make_task'"),
    method: Optional[str] = typer.Option(None, help="method name: CORL or a row of Fig. 1 (default: CORL+PIBU for "
                                                     "the built-in tasks, CORL for your own)"),
    seed: Optional[int] = typer.Option(None, help="seed (default 0)"),
    out: Path = typer.Option(Path("results/run"), help="output folder for summary.json"),
    store: Optional[Path] = typer.Option(None, help="run store (default OUT/run.corl)"),
    resume: bool = typer.Option(False, "--resume", help="continue the store's latest run exactly (or start one)"),
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
    video: bool = typer.Option(True, "--video/--no-video", help="render demonstration vs learned motion"),
    rollout_every_step: Optional[bool] = typer.Option(
        None, "--rollout-every-step/--no-rollout-every-step",
        help="roll out every motion-optimization step (default: the task's CORLConfig), or only the converged one"),
) -> None:
    """One learning run, every trial committed to the store; writes OUT/summary.json, figures, video."""
    import time

    from corl.errors import CorlError
    from corl.experiments.run_output import run_summary, run_text, task_extras, write_run_artifacts
    from corl.methods import DEFAULT_METHOD, METHODS
    from corl.session import StoredRun
    from corl.tasks.registry import BUILTIN_TASKS, load_task

    store_path = store or out / "run.corl"
    check_args(task=("TASK", task), seed=("--seed", seed), folder=("--out", out), store=("--store", store_path))
    if method is not None and method not in METHODS:
        fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    NEW_PATHS.track(out, store_path)
    t0 = time.perf_counter()
    try:
        peeked = latest_run(store_path) if resume else None  # read-only: the seed to build the task with
        task_seed = (0 if seed is None else seed) if peeked is None else int(peeked.seed or 0)
        the_task = load_task(task, seed=task_seed)  # before any file is created
        db = open_store(store_path)
    except CorlError as exc:
        fail(str(exc))
    with db:
        try:
            info = db.latest_run() if resume else None
            if resume and info is None and not quiet:
                typer.echo(f"--resume: {store_path} holds no run yet (killed before its first commit?); "
                           "starting one", err=True)
            if info is not None:
                stored_every = info.config.get("corl_overrides", {}).get("rollout_every_step")
                for flag, given, stored in (("--method", method, info.method), ("--seed", seed, info.seed),
                                            ("--[no-]rollout-every-step", rollout_every_step, stored_every)):
                    if given is not None and given != stored:
                        fail(f"{flag} {given} differs from the run being resumed ({stored}); drop the flag")
                method, seed = info.method, int(info.seed or 0)
                if seed != task_seed:  # another process started a run meanwhile
                    the_task = load_task(task, seed=seed)
                session = StoredRun.open(db, the_task, info.id)
            else:
                method = method or ("CORL+PIBU" if task in BUILTIN_TASKS else DEFAULT_METHOD)
                seed = 0 if seed is None else seed
                if seed != task_seed:
                    the_task = load_task(task, seed=seed)
                overrides = None if rollout_every_step is None else {"rollout_every_step": rollout_every_step}
                session = StoredRun.start(db, the_task, task_spec=task, method=method, seed=seed,
                                          corl_overrides=overrides)
        except CorlError as exc:
            fail(str(exc))

        import numpy as np

        def line(p, o):  # the --log line of one trial
            r = "-" if o.return_ is None else f"{o.return_:+.4f}"
            return (f"trial {p.index:4d}  round {p.round}  {p.step:14s} "
                    f"theta={np.round(p.theta, 4).tolist()} {'success' if o.success else 'FAILURE'}  R={r}")

        budget = getattr(getattr(session.learner, "optimizer", None), "max_evals", None)  # methods over w only
        with progress_tracker(f"run {method}", quiet=quiet, log=log, json_out=json_out) as tracker:
            def best():
                return None if session.best is None else session.best.return_

            def tick(p, o):
                tracker.update("trials", done=p.index + 1, total=budget, failures=int(not o.success), best=best(),
                               note=f"round {p.round} {p.step}", line=line(p, o))

            if session.history:  # resumed: what the store already holds
                tracker.update("trials", done=len(session.history), total=budget, best=best(), note="resumed",
                               failures=sum(not o.success for _, o in session.history))
            try:
                session.run(the_task, callback=tick)
                tracker.update("trials", done=len(session.history), total=len(session.history), note="finished")
            except CorlError as exc:
                fail(f"{exc} (the store {store_path} keeps every trial so far; resume with --resume)")
            payload = run_summary(the_task, method, seed, session.learner, time.perf_counter() - t0)
            payload["store"] = str(store_path)
            payload["run_id"] = session.run_id
            payload.update(task_extras(the_task, session.learner))
            tracker.message("writing figures and video ..." if video else "writing figures ...")
            payload["files"] = write_run_artifacts(the_task, session.learner, out, video=video)
    write_json(out / "summary.json", payload)
    if json_out:
        return print_json(payload)
    typer.echo(run_text(payload, out / "summary.json"))


def ask(
    store: Path = typer.Option(..., help="run store"),
    task: str = typer.Option(..., help="the task: 'synthetic' or 'package.module:make_task'"),
    method: str = typer.Option("CORL+PIBU", help="method, used when the store has no run yet"),
    seed: int = typer.Option(0, help="seed, used when the store has no run yet"),
    rate: float = typer.Option(100.0, help="rate of the written trajectory (Hz)"),
    out: Optional[Path] = typer.Option(None, help="folder for trial_<i>.csv/.npz (default: beside the store)"),
    raw: bool = typer.Option(False, "--raw", help="for a task without reference(): write the raw parameters w "
                                                 "(trial_<i>_raw_parameters.csv), NOT a joint trajectory"),
) -> None:
    """Write the next trial's trajectory (CSV and NPZ) and print its theta (real-robot loop)."""
    import numpy as np

    from corl.errors import CorlError
    from corl.methods import METHODS
    from corl.session import StoredRun, trajectory_of
    from corl.tasks.registry import load_task

    check_args(task=("--task", task), seed=("--seed", seed), rate=("--rate", rate), store=("--store", store),
               folder=("--out", out))
    if method not in METHODS:
        fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    NEW_PATHS.track(store, *([out] if out is not None else []))
    try:
        peeked = latest_run(store)  # read-only: the seed to build the task with
        task_seed = seed if peeked is None else int(peeked.seed or 0)
        the_task = load_task(task, seed=task_seed)  # before any file is created
        with open_store(store) as db:
            info = db.latest_run()
            if info is not None and int(info.seed or 0) != task_seed:  # another process started a run meanwhile
                the_task = load_task(task, seed=int(info.seed or 0))
            if getattr(the_task, "reference", None) is None and not raw:  # corl.problem.HasReference
                trajectory_of(the_task, np.zeros(1), rate)  # raises the message, before a trial is handed out
            if info is None:
                session = StoredRun.start(db, the_task, task_spec=task, method=method, seed=seed)
            else:
                session = StoredRun.open(db, the_task, info.id)
            if session.done:
                fail(f"run {session.run_id} has finished; 'corl status --store {store}' shows its result", code=1)
            proposal = session.ask()
            if raw:
                from corl.experiments.sweep import write_raw_parameters

                return typer.echo(json.dumps(write_raw_parameters(proposal, out or store.parent)))
            t, q = trajectory_of(the_task, proposal.w, rate)
    except CorlError as exc:
        fail(str(exc))
    folder = out or store.parent
    folder.mkdir(parents=True, exist_ok=True)
    stem = folder / f"trial_{proposal.index:04d}"
    np.savez(stem.with_suffix(".npz"), t=t, q=q, w=proposal.w, theta=proposal.theta)
    names = getattr(the_task, "joint_names", None) or [f"q{j}" for j in range(q.shape[1])]
    header = "t," + ",".join(names)
    np.savetxt(stem.with_suffix(".csv"), np.column_stack([t, q]), delimiter=",", header=header, comments="")
    typer.echo(json.dumps({"trial": proposal.index, "step": proposal.step, "round": proposal.round,
                           "theta": proposal.theta.tolist(), "csv": str(stem.with_suffix(".csv")),
                           "npz": str(stem.with_suffix(".npz"))}))


def tell(
    store: Path = typer.Option(..., help="run store"),
    task: str = typer.Option(..., help="the task: 'synthetic' or 'package.module:make_task'"),
    success: str = typer.Option(..., help="did the trial succeed: yes or no"),
    return_: Optional[str] = typer.Option(None, "--return", help="the measured return (needed on success)"),
) -> None:
    """Record the outcome of the pending trial."""
    import math

    from corl.errors import CorlError
    from corl.problem import Outcome
    from corl.session import StoredRun
    from corl.tasks.registry import load_task

    flag = success.strip().lower()
    if flag not in ("yes", "no"):
        fail(f"--success must be yes or no, got {success!r}")
    check_args(task=("--task", task), store=("--store", store))
    if flag == "no" and return_ is not None:
        fail(f"a failed trial is told without a return: drop --return {return_} (or say --success yes if the "
             "trial succeeded); nothing was stored")
    value = None
    if return_ is not None:
        try:
            value = float(return_)
        except ValueError:
            fail(f"--return must be a number, got {return_!r}")
        if not math.isfinite(value):
            fail(f"--return must be finite, got {return_!r}")
    try:
        outcome = Outcome(flag == "yes", value)
        with open_store(store, create=False) as db:
            info = db.latest_run()
            if info is None:
                fail(f"{store} holds no run; start one with 'corl ask'")
            if db.pending(info.id) is None:
                fail("there is no pending trial to tell (each trial is told once): run 'corl ask' first")
            session = StoredRun.open(db, load_task(task, seed=int(info.seed or 0)), info.id)
            session.tell(outcome)
            typer.echo(json.dumps({"trial": len(session.history) - 1, "success": outcome.success,
                                   "return": outcome.return_, "done": session.done}))
    except CorlError as exc:
        fail(str(exc))
