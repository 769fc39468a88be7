"""``corl bench synthetic``, ``corl bench door`` and ``corl sweep``: the studies of a simulated task
(:mod:`corl.experiments`)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from corl.arguments import MAX_STARTS, NEW_PATHS
from corl.cli.skill import P_MIN_OPTION, skill_settings
from corl.cli.common import (
    ADDRESS, BACKEND, JSON_OUT, LOG, QUIET, check_args, fail, make_folder, method_list, print_json, progress_tracker,
    write_json,
)

__all__ = ["bench_synthetic", "bench_door", "bench_contexts", "bench_parallel", "sweep"]


def bench_synthetic(
    starts: int = typer.Option(100, help=f"random feasible starts per method, at most {MAX_STARTS}"),
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
    from corl.experiments.synthetic import FOUND_TOLERANCE, aggregate, sweep
    from corl.experiments.tables import synthetic_table
    from corl.methods import METHODS, PAPER_FIG1
    from corl.tasks.synthetic import return_of
    from corl.versions import library_versions

    names = method_list(methods, default=list(PAPER_FIG1), allowed=METHODS)
    check_args(starts=("--starts", starts), seed=("--seed", seed), jobs=("--jobs", jobs), folder=("--out", out))
    NEW_PATHS.track(out)
    t0 = time.perf_counter()
    with progress_tracker("bench synthetic", quiet=quiet, log=log, json_out=json_out) as tracker:
        for name in names:
            tracker.add_stage(name, total=starts)

        def tick(r):  # one row per method: starts done, failures, best R = R(theta(w_best))
            ret = None if r.best_w is None else return_of(math.atan2(r.best_w[1], r.best_w[0]))
            tracker.update(r.method, advance=1, total=starts, failures=r.failures, ret=ret,
                           note=f"start {r.start}: {'found' if r.found else 'not found'}, {r.failures} failures")

        try:
            results = sweep(names, starts, seed, jobs=jobs, backend=backend, address=address, progress=tick)
        except CorlError as exc:
            fail(str(exc))
    wall = time.perf_counter() - t0
    table = aggregate(results, names)
    payload = {"methods": table, "found_tolerance": FOUND_TOLERANCE, "seed": seed, "starts": starts,
               "wall_seconds": wall, "versions": library_versions()}
    write_json(out / "synthetic.json", payload)
    if json_out:
        return print_json({**payload, "file": str(out / "synthetic.json")})
    typer.echo(synthetic_table(table, FOUND_TOLERANCE))
    typer.echo(f"\n{len(names)} methods x {starts} starts in {wall:.1f} s; wrote {out / 'synthetic.json'}")


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
    from corl.experiments.door import DOOR_METHODS, door_sweep
    from corl.experiments.figures import plot_trial_curves
    from corl.experiments.sweep import check_grid
    from corl.experiments.tables import curves_table, door_table
    from corl.tasks.door.task import FORCE_REFERENCE
    from corl.versions import library_versions

    names = method_list(methods, default=list(DOOR_METHODS), allowed=DOOR_METHODS)
    if min(seeds, iterations, dmp_iterations) < 1:
        fail("--seeds, --iterations and --dmp-iterations must be at least 1")
    if not 0.0 <= force_noise < float("inf"):
        fail(f"--force-noise is a standard deviation in N and must be finite and >= 0, got {force_noise}")
    try:
        n1, n2 = (int(v) for v in grid.lower().split("x"))
    except ValueError:
        fail(f"--grid must look like 25x15, got {grid!r}")
    if min(n1, n2) < 2:
        fail(f"--grid needs at least 2 points per axis, got {grid!r}")
    try:  # the safe regions are sweeps: the same cap, checked before the runs
        check_grid((n1, n2), 2, what=f"--grid {grid!r}")
    except CorlError as exc:
        fail(str(exc))
    check_args(jobs=("--jobs", jobs), folder=("--out", out))
    NEW_PATHS.track(out)
    t0 = time.perf_counter()
    with progress_tracker("bench door", quiet=quiet, log=log, json_out=json_out) as tracker:
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
            fail(str(exc))
    wall = time.perf_counter() - t0
    regions = {r.key: {"grid": list(r.success.shape), "safe": int(r.success.sum()),
                       "unrealised": int((~r.realised).sum()), "spacing": r.spacing.tolist()}
               for r in result.regions.values()}
    payload = {"methods": result.table, "seeds": seeds, "iterations": iterations, "dmp_iterations": dmp_iterations,
               "force_noise": force_noise, "safe_regions": regions, "curves": result.curves, "wall_seconds": wall,
               "versions": library_versions()}
    write_json(out / "door.json", payload)
    figure = plot_trial_curves(result.curves, out / "door_curves.png")
    if json_out:
        return print_json({**payload, "file": str(out / "door.json"), "figure": str(figure)})
    typer.echo(door_table(result.table, iterations=iterations, dmp_iterations=dmp_iterations,
                          force_reference=FORCE_REFERENCE,
                          regions=result.regions))
    typer.echo("\n" + curves_table(result.curves))
    typer.echo(f"\n{len(names)} methods x {seeds} seeds in {wall:.1f} s; wrote {out / 'door.json'} and {figure}")


def sweep(
    task: str = typer.Argument(..., help="'synthetic', 'door', or an import path 'package.module:make_task'"),
    grid: str = typer.Option(..., help="points per theta coordinate, e.g. 25,15 (one number: every coordinate); "
                                       "at most 1000000 points in all (MAX_SWEEP_POINTS)"),
    out: Path = typer.Option(Path("results/sweep"), help="folder for sweep.csv, sweep.json and sweep.png"),
    seed: int = typer.Option(0, help="seed the task factory gets (when it takes one)"),
    jobs: int = typer.Option(1, help="parallel workers (-1: all cores)"),
    context: Optional[str] = typer.Option(None, help="sweep the task in this scene (a task with contexts), from the "
                                                     "scene's own demonstration: comma-separated numbers, e.g. 0.02,-0.01"),
    backend: str = BACKEND, address: Optional[str] = ADDRESS,
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
) -> None:
    """Ground truth of a simulated task: success and return over a theta grid, each theta realised
    from the demonstration with Eq. 18 as the learner does it, then rolled out (in scene --context C: from
    that scene's demonstration)."""
    from corl.errors import CorlError
    from corl.experiments.sweep import TaskSpec, sweep_command

    check_args(task=("TASK", task), seed=("--seed", seed), jobs=("--jobs", jobs), folder=("--out", out))
    c = None
    if context is not None:
        from corl.cli.skill import parse_context

        try:
            c = parse_context(TaskSpec(task, seed)(), context)
        except CorlError as exc:
            fail(str(exc))
    NEW_PATHS.track(out)
    make_folder("--out", out)
    try:
        with progress_tracker(f"sweep {task}", quiet=quiet, log=log, json_out=json_out) as tracker:
            payload = sweep_command(task, grid, out, seed=seed, jobs=jobs, backend=backend, address=address,
                                    tracker=tracker, context=c)
    except CorlError as exc:
        fail(str(exc))
    if json_out:
        return print_json(payload)
    typer.echo(f"{payload['successes']}/{payload['points']} grid points succeed ({payload['unrealised']} unrealisable); "
               f"wrote {', '.join(v for k, v in payload['files'].items() if not k.endswith('_skipped'))}")



def bench_contexts(
    task: str = typer.Argument(..., help="a task with contexts: 'synthetic-context', 'door', or 'package.module:make_task'"),
    train: int = typer.Option(8, help="training contexts: the demonstration's own, then TRAIN-1 drawn from the box"),
    test: int = typer.Option(8, help="held-out test contexts drawn from the box"),
    seed: int = typer.Option(0, help="seed of the contexts and the methods"),
    budget: int = typer.Option(40, help="trials per method and test context (each stops earlier when it converges)"),
    out: Path = typer.Option(Path("results/contexts"), help="output folder for contexts.json, the figure, train.corl"),
    jobs: int = typer.Option(2, help="parallel workers over the test contexts (-1: all cores)"),
    truth: str = typer.Option("auto", help="each test scene's best return: auto (the task's best_return() when it "
                              "has one, else grid:64), task, or grid:N (a sweep of N thetas from its demonstration)"),
    p_min: Optional[str] = P_MIN_OPTION,
    robots: int = typer.Option(1, help="K robots: the training contexts K at a time, each in its own process, each "
                               "scene learning from the earlier waves' runs (1: in turn, each from all before it)"),
    trial_seconds: float = typer.Option(0.0, help="robot time each training trial also takes, in seconds"),
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
) -> None:
    """One skill, many scenes: the skill learned on TRAIN contexts against learning each test context
    from scratch and against the nearest training context's motion, beside a sweep of each test context."""
    import time

    from corl.errors import CorlError
    from corl.experiments.context_training import check_robots
    from corl.experiments.contexts import bench_contexts as study, contexts_table, parse_truth, plot_contexts

    check_args(task=("TASK", task), seed=("--seed", seed), jobs=("--jobs", jobs), folder=("--out", out))
    for flag, value, low, high in (("--train", train, 1, 1000), ("--test", test, 1, 1000), ("--budget", budget, 1, 10000)):
        if not low <= value <= high:
            fail(f"{flag} must be an integer in [{low}, {high}], got {value}")
    try:
        parse_truth(truth)
        check_robots(robots, trial_seconds)
    except CorlError as exc:
        fail(str(exc))
    skill_kw = skill_settings(p_min)  # every study learns in scenes
    NEW_PATHS.track(out)
    make_folder("--out", out)
    t0 = time.perf_counter()
    with progress_tracker(f"bench contexts {task}", quiet=quiet, log=log, json_out=json_out) as tracker:
        tracker.add_stage("train", total=train)
        tracker.add_stage("test", total=test)

        def tick(stage, done, total, row):
            if "skipped" in row:
                return tracker.update(stage, done=done, total=total, note=f"context {done} skipped: {row['skipped']}")
            if stage == "train":
                note = f"context {done}: {row['trials']} trials, {row['failures']} failed, start {row['start']}"
                return tracker.update("train", done=done, total=total, failures=row["failures"], note=note)
            c = row["contextual"]
            tracker.update("test", done=done, total=total, failures=c["failures"],
                           note=f"contextual: {c['trials_to_95']} trials to 95%, scratch {row['scratch']['trials_to_95']}")

        try:
            payload = study(task, train_count=train, test_count=test, seed=seed, out=out, budget=budget, jobs=jobs,
                            progress=tick, truth=truth, skill=skill_kw, robots=robots, trial_seconds=trial_seconds)
        except CorlError as exc:
            fail(str(exc))
    payload["wall_seconds"] = time.perf_counter() - t0
    write_json(out / "contexts.json", payload)
    figure = plot_contexts(payload, out / "contexts_theta.png", labels=payload.get("theta_labels"))
    if json_out:
        return print_json({**payload, "file": str(out / "contexts.json"), "figure": str(figure)})
    typer.echo(contexts_table(payload))
    typer.echo(f"\n{train} training and {test} test contexts in {payload['wall_seconds']:.1f} s (training "
               f"{payload['train_seconds']:.1f} s, {robots} robot{'' if robots == 1 else 's'}); wrote "
               f"{out / 'contexts.json'}, {figure} and the skill's store {out / 'train.corl'}")


def bench_parallel(
    task: str = typer.Argument(..., help="'synthetic', 'door', or an import path 'package.module:make_task'"),
    robots: int = typer.Option(4, help="K, the robots of the second run (the first has one)"),
    trial_seconds: float = typer.Option(0.5, help="robot time each trial also takes, in seconds"),
    seed: int = typer.Option(0, help="seed of the task and the learner"),
    backend: str = typer.Option("local", help="where the trials run: local (worker processes), ray (Ray actors) or "
                                               "dask (Dask workers), on a local cluster unless --address"),
    address: Optional[str] = typer.Option(None, help="with --backend ray or dask: a running cluster to join"),
    out: Path = typer.Option(Path("results/parallel"), help="output folder for parallel.json and parallel.png"),
    rollout_every_step: Optional[bool] = typer.Option(
        None, "--rollout-every-step/--no-rollout-every-step", help="as corl run (default: the task's CORLConfig)"),
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
) -> None:
    """One robot against K: the same CORL learning, each trial taking S more seconds; writes parallel.json."""
    import math

    from corl.errors import CorlError
    from corl.experiments.parallel import parallel_bench, plot_parallel
    from corl.fleet import check_backend

    check_args(task=("TASK", task), seed=("--seed", seed), folder=("--out", out))
    if not isinstance(robots, int) or not 1 <= robots <= 64:
        fail(f"--robots must be an integer in [1, 64], got {robots}")
    if not (math.isfinite(trial_seconds) and 0 <= trial_seconds <= 3600):
        fail(f"--trial-seconds must be a number of seconds in [0, 3600], got {trial_seconds}")
    try:
        check_backend(backend, address)
    except CorlError as exc:
        fail(str(exc))
    NEW_PATHS.track(out)
    make_folder("--out", out)
    overrides = None if rollout_every_step is None else {"rollout_every_step": rollout_every_step}
    with progress_tracker("bench parallel", quiet=quiet, log=log, json_out=json_out) as tracker:
        def tick(k, p, o, session):
            best = session.best
            tracker.update(f"{k} robot{'' if k == 1 else 's'}", done=len(session.history), total=None,
                           failures=int(not o.success), best=None if best is None else best.return_,
                           note=f"trial {p.index} {p.step}")

        try:
            payload = parallel_bench(task, robots, trial_seconds, seed, out, overrides=overrides, backend=backend,
                                     address=address, progress=tick)
        except CorlError as exc:
            fail(str(exc))
    payload["files"] = {"json": str(out / "parallel.json"), "figure": str(plot_parallel(payload, out / "parallel.png"))}
    write_json(out / "parallel.json", payload)
    if json_out:
        return print_json({k: v for k, v in payload.items()})
    for k, r in payload["runs"].items():
        typer.echo(f"{k} robot{'' if k == '1' else 's'}: wall {r['wall_s']:.1f} s, {r['trials']} trials, "
                   f"{r['failures']} failure{'' if r['failures'] == 1 else 's'}, final return {r['final_return']}, "
                   f"out at once {r['out_at_once']}")
    typer.echo(f"wall time {payload['wall_ratio']:.2f}x one robot's; wrote {out / 'parallel.json'}")
