"""The ``corl`` command line: learning runs and benchmarks.

Heavy modules (numpy-heavy learners, joblib, matplotlib, MuJoCo) are imported inside the commands
so that ``corl --help`` stays fast.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Optional

import typer

from corl.arguments import NEW_PATHS, check, latest_run  # light: no numpy
from corl.errors import CorlError

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="corl: learn a manipulation skill from one demonstration (Englert & Toussaint, RSS 2016).")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks that reproduce the paper's tables.")
app.add_typer(bench_app, name="bench")


def _fail(message: str, code: int = 2) -> None:
    """Print ``error: message`` and exit; what the command created is removed while still empty."""
    typer.echo(f"error: {message}", err=True)
    NEW_PATHS.remove_if_empty()
    raise typer.Exit(code)


def _check(**args) -> None:
    """:func:`corl.arguments.check` of the arguments, before any rollout or file; the first bad one exits 2."""
    try:
        check(**args)
    except CorlError as exc:
        _fail(str(exc))


def _method_list(methods: Optional[str], *, default: list[str], allowed) -> list[str]:
    """Comma-separated method names, checked against ``allowed``; ``default`` when None."""
    names = default if methods is None else [m.strip() for m in methods.split(",") if m.strip()]
    unknown = [m for m in names if m not in allowed]
    if unknown:
        _fail(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(allowed)}")
    return names


def _write_json(path: Path, payload: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(payload, indent=2, sort_keys=False) + "\n")
    tmp.replace(path)


# Output options of the long commands (corl.progress): progress on stderr, the result on stdout.
QUIET = typer.Option(False, "--quiet", "-q", help="nothing on stderr but errors")
JSON_OUT = typer.Option(False, "--json", help="stdout: one JSON document and nothing else")
LOG = typer.Option(False, "--log", help="plain progress lines, not the live display (default if stderr is no terminal)")


def _tracker(title: str, *, quiet: bool, log: bool, json_out: bool):
    """The command's :class:`corl.progress.Tracker`; with ``--json`` stray prints go to stderr."""
    from corl.progress import Tracker, choose_mode

    return Tracker(choose_mode(quiet=quiet, log=log), title, protect_stdout=json_out)


def _print_json(payload: dict) -> None:
    typer.echo(json.dumps(payload, indent=2))


# Where the runs of a benchmark go (corl.experiments.backends).
BACKEND = typer.Option("loky", help="where runs execute: loky (local processes), ray or dask (a cluster)")
ADDRESS = typer.Option(None, help="a running Ray (auto, HOST:PORT) or Dask (tcp://HOST:8786) cluster to use; "
                                  "default: start a local one with --jobs workers")


@bench_app.command("synthetic")
def bench_synthetic(
    starts: int = typer.Option(100, help="random feasible starts per method"),
    seed: int = typer.Option(0, help="seed of the starts and the methods"),
    out: Path = typer.Option(Path("results/synthetic"), help="output folder for synthetic.json"),
    methods: Optional[str] = typer.Option(None, help="comma-separated method names (default: the 8 of Fig. 1)"),
    jobs: int = typer.Option(-1, help="parallel workers (-1: all cores)"),
    backend: str = BACKEND, address: Optional[str] = ADDRESS,
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
) -> None:
    """Reproduce Fig. 1: every method from the same random feasible starts."""
    import math
    import time

    from corl.errors import CorlError
    from corl.experiments.methods import METHODS, PAPER_FIG1
    from corl.experiments.report import synthetic_table
    from corl.experiments.synthetic import FOUND_TOLERANCE, aggregate, sweep
    from corl.tasks.synthetic import return_of
    from corl.versions import library_versions

    names = _method_list(methods, default=list(PAPER_FIG1), allowed=METHODS)
    if starts < 1:
        _fail("--starts must be at least 1")
    _check(seed=("--seed", seed), jobs=("--jobs", jobs), folder=("--out", out))
    NEW_PATHS.track(out)
    t0 = time.perf_counter()
    with _tracker("bench synthetic", quiet=quiet, log=log, json_out=json_out) as tracker:
        for name in names:
            tracker.add_stage(name, total=starts)

        def tick(r):  # one row per method: starts done, failures, best R = R(theta(w_best))
            ret = None if r.best_w is None else return_of(math.atan2(r.best_w[1], r.best_w[0]))
            tracker.update(r.method, advance=1, total=starts, failures=r.failures, ret=ret,
                           note=f"start {r.start}: {'found' if r.found else 'not found'}, {r.failures} failures")

        try:
            results = sweep(names, starts, seed, jobs=jobs, backend=backend, address=address, progress=tick)
        except CorlError as exc:
            _fail(str(exc))
    wall = time.perf_counter() - t0
    table = aggregate(results, names)
    payload = {"methods": table, "found_tolerance": FOUND_TOLERANCE, "seed": seed, "starts": starts,
               "wall_seconds": wall, "versions": library_versions()}
    _write_json(out / "synthetic.json", payload)
    if json_out:
        return _print_json({**payload, "file": str(out / "synthetic.json")})
    typer.echo(synthetic_table(table, FOUND_TOLERANCE))
    typer.echo(f"\n{len(names)} methods x {starts} starts in {wall:.1f} s; wrote {out / 'synthetic.json'}")


@bench_app.command("door")
def bench_door(
    seeds: int = typer.Option(10, help="runs per method, seeds 0 .. SEEDS-1"),
    iterations: int = typer.Option(100, help="black-box trials of CORL's step 2 (one round)"),
    dmp_iterations: int = typer.Option(150, help="PoWER trials of the DMP+PoWER baseline"),
    out: Path = typer.Option(Path("results/door"), help="output folder for door.json and the safe-region cache"),
    methods: Optional[str] = typer.Option(None, help="comma-separated: CORL+PIBU,CORL+CMA,DMP+PoWER (default all)"),
    grid: str = typer.Option("25x15", help="safe-region grid over theta, N1xN2"),
    force_noise: float = typer.Option(0.0, help="std (N) of a seeded error of the force sensor behind R; "
                                                "0: exact simulator, every seed of a deterministic method alike"),
    jobs: int = typer.Option(2, help="parallel workers (-1: all cores)"),
    backend: str = BACKEND, address: Optional[str] = ADDRESS,
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
) -> None:
    """Reproduce Fig. 3: the door task's highest return, failure rate and distance to the safe region."""
    import time

    from corl.errors import CorlError
    from corl.experiments.door_bench import DOOR_METHODS, door_sweep
    from corl.experiments.door_curves import curves_table, plot_trial_curves
    from corl.experiments.report import door_table
    from corl.tasks.door.task import FORCE_REFERENCE
    from corl.versions import library_versions

    names = _method_list(methods, default=list(DOOR_METHODS), allowed=DOOR_METHODS)
    if min(seeds, iterations, dmp_iterations) < 1:
        _fail("--seeds, --iterations and --dmp-iterations must be at least 1")
    if not 0.0 <= force_noise < float("inf"):
        _fail(f"--force-noise is a standard deviation in N and must be finite and >= 0, got {force_noise}")
    try:
        n1, n2 = (int(v) for v in grid.lower().split("x"))
    except ValueError:
        _fail(f"--grid must look like 25x15, got {grid!r}")
    if min(n1, n2) < 2:
        _fail(f"--grid needs at least 2 points per axis, got {grid!r}")
    _check(jobs=("--jobs", jobs), folder=("--out", out))
    NEW_PATHS.track(out)
    t0 = time.perf_counter()
    with _tracker("bench door", quiet=quiet, log=log, json_out=json_out) as tracker:
        for name in names:
            tracker.add_stage(name, total=seeds)

        def tick(stage, done, total, note, run=None):  # one row per method, then one per safe region
            if run is None:
                return tracker.update(stage, done=done, total=total, note=note)
            tracker.update(run.method, advance=1, total=seeds, failures=run.failures, ret=run.highest_return,
                           note=f"seed {run.seed}: {run.failures}/{run.trials} failed")

        try:
            result = door_sweep(names, seeds, iterations, out=out, dmp_iterations=dmp_iterations, grid=(n1, n2),
                                jobs=jobs, backend=backend, address=address, progress=tick, force_noise=force_noise)
        except CorlError as exc:
            _fail(str(exc))
    wall = time.perf_counter() - t0
    regions = {r.key: {"grid": list(r.success.shape), "safe": int(r.success.sum()),
                       "unrealised": int((~r.realised).sum()), "spacing": r.spacing.tolist()}
               for r in result.regions.values()}
    payload = {"methods": result.table, "seeds": seeds, "iterations": iterations, "dmp_iterations": dmp_iterations,
               "force_noise": force_noise, "safe_regions": regions, "curves": result.curves, "wall_seconds": wall,
               "versions": library_versions()}
    _write_json(out / "door.json", payload)
    figure = plot_trial_curves(result.curves, out / "door_curves.png")
    if json_out:
        return _print_json({**payload, "file": str(out / "door.json"), "figure": str(figure)})
    typer.echo(door_table(result.table, iterations=iterations, dmp_iterations=dmp_iterations,
                          force_reference=FORCE_REFERENCE,
                          regions=result.regions))
    typer.echo("\n" + curves_table(result.curves))
    typer.echo(f"\n{len(names)} methods x {seeds} seeds in {wall:.1f} s; wrote {out / 'door.json'} and {figure}")


@app.command("sweep")
def sweep(
    task: str = typer.Argument(..., help="'synthetic', 'door', or an import path 'package.module:make_task'"),
    grid: str = typer.Option(..., help="points per theta coordinate, e.g. 25,15 (one number: every coordinate)"),
    out: Path = typer.Option(Path("results/sweep"), help="folder for sweep.csv, sweep.json and sweep.png"),
    seed: int = typer.Option(0, help="seed the task factory gets (when it takes one)"),
    jobs: int = typer.Option(1, help="parallel workers (-1: all cores)"),
    backend: str = BACKEND, address: Optional[str] = ADDRESS,
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
) -> None:
    """Ground truth of a simulated task: success and return over a theta grid, each theta realised
    from the demonstration with Eq. 18 as the learner does it, then rolled out."""
    from corl.errors import CorlError
    from corl.experiments.sweep import sweep_command

    try:
        with _tracker(f"sweep {task}", quiet=quiet, log=log, json_out=json_out) as tracker:
            payload = sweep_command(task, grid, out, seed=seed, jobs=jobs, backend=backend, address=address,
                                    tracker=tracker)
    except CorlError as exc:
        _fail(str(exc))
    if json_out:
        return _print_json(payload)
    typer.echo(f"{payload['successes']}/{payload['points']} grid points succeed ({payload['unrealised']} unrealisable); "
               f"wrote {', '.join(v for k, v in payload['files'].items() if not k.endswith('_skipped'))}")


def _open_store(path: Path, *, readonly: bool = False, create: bool = True):
    from corl.store import RunStore

    if not readonly and create:
        path.parent.mkdir(parents=True, exist_ok=True)
    return RunStore(path, readonly=readonly, create=create and not readonly)


@app.command("run")
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
    from corl.experiments.methods import DEFAULT_METHOD, METHODS
    from corl.experiments.summary import run_summary, run_text, task_extras
    from corl.session import StoredRun
    from corl.tasks.registry import BUILTIN_TASKS, load_task

    store_path = store or out / "run.corl"
    _check(task=("TASK", task), seed=("--seed", seed), folder=("--out", out), store=("--store", store_path))
    if method is not None and method not in METHODS:
        _fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    NEW_PATHS.track(out, store_path)
    t0 = time.perf_counter()
    try:
        peeked = latest_run(store_path) if resume else None  # read-only: the seed to build the task with
        task_seed = (0 if seed is None else seed) if peeked is None else int(peeked.seed or 0)
        the_task = load_task(task, seed=task_seed)  # before any file is created
        db = _open_store(store_path)
    except CorlError as exc:
        _fail(str(exc))
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
                        _fail(f"{flag} {given} differs from the run being resumed ({stored}); drop the flag")
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
            _fail(str(exc))

        import numpy as np

        def line(p, o):  # the --log line of one trial
            r = "-" if o.return_ is None else f"{o.return_:+.4f}"
            return (f"trial {p.index:4d}  round {p.round}  {p.step:14s} "
                    f"theta={np.round(p.theta, 4).tolist()} {'success' if o.success else 'FAILURE'}  R={r}")

        budget = getattr(getattr(session.learner, "optimizer", None), "max_evals", None)  # methods over w only
        with _tracker(f"run {method}", quiet=quiet, log=log, json_out=json_out) as tracker:
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
                _fail(f"{exc} (the store {store_path} keeps every trial so far; resume with --resume)")
            payload = run_summary(the_task, method, seed, session.learner, time.perf_counter() - t0)
            payload["store"] = str(store_path)
            payload["run_id"] = session.run_id
            payload.update(task_extras(the_task, session.learner))
            tracker.message("writing figures and video ..." if video else "writing figures ...")
            from corl.experiments.artifacts import write_run_artifacts

            payload["files"] = write_run_artifacts(the_task, session.learner, out, video=video)
    _write_json(out / "summary.json", payload)
    if json_out:
        return _print_json(payload)
    typer.echo(run_text(payload, out / "summary.json"))


@app.command("ask")
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
    from corl.experiments.methods import METHODS
    from corl.session import StoredRun, trajectory_of
    from corl.tasks.registry import load_task

    _check(task=("--task", task), seed=("--seed", seed), rate=("--rate", rate), store=("--store", store),
           folder=("--out", out))
    if method not in METHODS:
        _fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    NEW_PATHS.track(store, *([out] if out is not None else []))
    try:
        peeked = latest_run(store)  # read-only: the seed to build the task with
        task_seed = seed if peeked is None else int(peeked.seed or 0)
        the_task = load_task(task, seed=task_seed)  # before any file is created
        with _open_store(store) as db:
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
                _fail(f"run {session.run_id} has finished; 'corl status --store {store}' shows its result", code=1)
            proposal = session.ask()
            if raw:
                from corl.experiments.sweep import write_raw_parameters

                return typer.echo(json.dumps(write_raw_parameters(proposal, out or store.parent)))
            t, q = trajectory_of(the_task, proposal.w, rate)
    except CorlError as exc:
        _fail(str(exc))
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


@app.command("tell")
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
        _fail(f"--success must be yes or no, got {success!r}")
    _check(task=("--task", task), store=("--store", store))
    if flag == "no" and return_ is not None:
        _fail(f"a failed trial is told without a return: drop --return {return_} (or say --success yes if the "
              "trial succeeded); nothing was stored")
    value = None
    if return_ is not None:
        try:
            value = float(return_)
        except ValueError:
            _fail(f"--return must be a number, got {return_!r}")
        if not math.isfinite(value):
            _fail(f"--return must be finite, got {return_!r}")
    try:
        outcome = Outcome(flag == "yes", value)
        with _open_store(store, create=False) as db:
            info = db.latest_run()
            if info is None:
                _fail(f"{store} holds no run; start one with 'corl ask'")
            if db.pending(info.id) is None:
                _fail("there is no pending trial to tell (each trial is told once): run 'corl ask' first")
            session = StoredRun.open(db, load_task(task, seed=int(info.seed or 0)), info.id)
            session.tell(outcome)
            typer.echo(json.dumps({"trial": len(session.history) - 1, "success": outcome.success,
                                   "return": outcome.return_, "done": session.done}))
    except CorlError as exc:
        _fail(str(exc))


def _run_info(r) -> dict:
    """A :class:`corl.store.RunInfo` as JSON (``corl runs --json``, ``corl status --json``)."""
    return {"id": r.id, "task": r.task, "method": r.method, "seed": r.seed, "status": r.status.value,
            "created": r.created, "trials": r.n_trials, "told": r.n_told}


@app.command("status")
def status(store: Path = typer.Option(..., help="run store"),
           run_id: Optional[int] = typer.Option(None, "--run", help="run id (default: latest)"),
           json_out: bool = JSON_OUT) -> None:
    """Show a run: its configuration, trials so far, failures and the best trial."""
    from corl.errors import CorlError

    _check(path=("--store", store))
    try:
        with _open_store(store, readonly=True) as db:
            info = db.run(run_id) if run_id is not None else db.latest_run()
            if info is None:
                _fail(f"{store} holds no run yet", code=1)
            trials = db.trials(info.id)
    except CorlError as exc:
        _fail(str(exc))
    told = [t for t in trials if t.outcome is not None]
    ok = [t for t in told if t.outcome.success]
    best = max(ok, key=lambda t: t.outcome.return_, default=None)
    if json_out:
        return _print_json({**_run_info(info), "trials": len(trials), "told": len(told),
                            "pending": len(trials) - len(told), "failures": len(told) - len(ok),
                            "best": None if best is None else {"trial": best.index, "return": best.outcome.return_,
                                                               "theta": best.proposal.theta.tolist()}})
    typer.echo(f"run {info.id}: task {info.task}, method {info.method}, seed {info.seed}, {info.status.value}")
    typer.echo(f"trials {len(trials)} (told {len(told)}, pending {len(trials) - len(told)}), "
               f"failures {len(told) - len(ok)}")
    if best is not None:
        typer.echo(f"best return {best.outcome.return_:.6g} at trial {best.index}, "
                   f"theta {[round(float(v), 6) for v in best.proposal.theta]}")


@app.command("runs")
def runs(store: Path = typer.Option(..., help="run store"), json_out: bool = JSON_OUT) -> None:
    """List a store's runs."""
    from corl.errors import CorlError

    _check(path=("--store", store))
    try:
        with _open_store(store, readonly=True) as db:
            infos = db.runs()
    except CorlError as exc:
        _fail(str(exc))
    if json_out:
        return _print_json({"runs": [_run_info(r) for r in infos]})
    typer.echo(f"{'id':>4} {'task':<12} {'method':<20} {'seed':>6} {'trials':>7} {'status':<9} created")
    for r in infos:
        typer.echo(f"{r.id:>4} {r.task:<12} {r.method:<20} {r.seed!s:>6} {r.n_trials:>7} {r.status.value:<9} {r.created}")


@app.command("export")
def export(store: Path = typer.Option(..., help="run store"),
           out: Path = typer.Option(..., help="file to write: .csv or .parquet (w vectors go beside it as .npz)"),
           run_id: Optional[int] = typer.Option(None, "--run", help="run id (default: latest)")) -> None:
    """Export a run's trials for analysis."""
    from corl.errors import CorlError

    _check(path=("--store", store), export=("--out", out))
    try:
        with _open_store(store, readonly=True) as db:
            info = db.run(run_id) if run_id is not None else db.latest_run()
            if info is None:
                _fail(f"{store} holds no run yet", code=1)
            table, arrays = db.export(info.id, out)
    except CorlError as exc:
        _fail(str(exc))
    typer.echo(f"wrote {table} and {arrays}")


@app.command("report")
def report(store: Path = typer.Option(..., help="run store"),
           out: Path = typer.Option(..., help="folder for the pages run_<id>.html (and index.html)"),
           run_id: Optional[int] = typer.Option(None, "--run", help="run id (default: every run)"),
           video: bool = typer.Option(True, "--video/--no-video", help="embed the video for tasks that render"),
           task: Optional[str] = typer.Option(None, help="the runs' task, as given to 'corl run' (never read "
                                                        "from the store); without it the pages show stored data only"),
           quiet: bool = QUIET, json_out: bool = JSON_OUT) -> None:
    """One self-contained HTML page per run: configuration, versions, curves, return map, trials, video."""
    from corl.errors import CorlError
    from corl.experiments.html_report import write_reports

    _check(path=("--store", store), task=("--task", task), folder=("--out", out))
    NEW_PATHS.track(out)
    with _tracker("report", quiet=quiet, log=True, json_out=json_out) as tracker:  # messages only
        try:
            pages = write_reports(store, out, run_id=run_id, video=video, log=tracker.message, task_spec=task)
        except CorlError as exc:
            _fail(str(exc))
    if json_out:
        return _print_json({"store": str(store), "pages": [str(page) for page in pages]})
    for page in pages:
        typer.echo(str(page))


def main() -> None:
    """The ``corl`` entry point: a bug that escapes a command prints one line, not a traceback."""
    try:
        app()
    except Exception as exc:  # not a usage error: every one of those exits 2 with its own message
        if os.environ.get("CORL_DEBUG"):
            raise
        typer.echo(f"error: internal error {type(exc).__name__}: {exc}. This is a bug in corl or in the task; "
                   "set CORL_DEBUG=1 to see the traceback, and please report it", err=True)
        sys.exit(1)


if __name__ == "__main__":
    sys.exit(main())
