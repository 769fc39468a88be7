"""The ``corl`` command line: learning runs and benchmarks.

Heavy modules (numpy-heavy learners, joblib, matplotlib, MuJoCo) are imported inside the commands
so that ``corl --help`` stays fast.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Optional

import typer

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="corl: learn a manipulation skill from one demonstration (Englert & Toussaint, RSS 2016).")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks that reproduce the paper's tables.")
app.add_typer(bench_app, name="bench")


def _fail(message: str, code: int = 2) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code)


def _write_json(path: Path, payload: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(payload, indent=2, sort_keys=False) + "\n")
    tmp.replace(path)


@bench_app.command("synthetic")
def bench_synthetic(
    starts: int = typer.Option(100, help="random feasible starts per method"),
    seed: int = typer.Option(0, help="seed of the starts and the methods"),
    out: Path = typer.Option(Path("results/synthetic"), help="output folder for synthetic.json"),
    methods: Optional[str] = typer.Option(None, help="comma-separated method names (default: the 8 of Fig. 1)"),
    jobs: int = typer.Option(-1, help="parallel workers (-1: all cores)"),
    backend: str = typer.Option("loky", help="joblib backend"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress bar"),
) -> None:
    """Reproduce Fig. 1: every method from the same random feasible starts."""
    import time

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from corl.errors import CorlError
    from corl.experiments.methods import METHODS, PAPER_FIG1
    from corl.experiments.report import synthetic_table
    from corl.experiments.synthetic import FOUND_TOLERANCE, aggregate, sweep
    from corl.versions import library_versions

    names = list(PAPER_FIG1) if methods is None else [m.strip() for m in methods.split(",") if m.strip()]
    unknown = [m for m in names if m not in METHODS]
    if unknown:
        _fail(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(METHODS)}")
    if starts < 1:
        _fail("--starts must be at least 1")
    console = Console(stderr=True)
    t0 = time.perf_counter()
    with Progress(TextColumn("[bold]synthetic"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TextColumn("{task.description}"), console=console, disable=quiet) as bar:
        job = bar.add_task("", total=starts * len(names))
        failures = {m: 0 for m in names}

        def tick(r):
            failures[r.method] += r.failures
            bar.update(job, advance=1, description=f"{r.method}: {failures[r.method]} failures so far")

        try:
            results = sweep(names, starts, seed, jobs=jobs, backend=backend, progress=tick)
        except CorlError as exc:
            _fail(str(exc))
    wall = time.perf_counter() - t0
    table = aggregate(results, names)
    payload = {"methods": table, "found_tolerance": FOUND_TOLERANCE, "seed": seed, "starts": starts,
               "wall_seconds": wall, "versions": library_versions()}
    _write_json(out / "synthetic.json", payload)
    typer.echo(synthetic_table(table, FOUND_TOLERANCE))
    typer.echo(f"\n{len(names)} methods x {starts} starts in {wall:.1f} s; wrote {out / 'synthetic.json'}")


@app.command("run")
def run(
    task: str = typer.Argument(..., help="'synthetic', or an import path 'package.module:make_task'"),
    method: str = typer.Option("CORL+PIBU", help="method name (a row of Fig. 1)"),
    seed: int = typer.Option(0, help="seed"),
    out: Path = typer.Option(Path("results/run"), help="output folder for summary.json"),
    quiet: bool = typer.Option(False, "--quiet", help="no progress output"),
) -> None:
    """One learning run; writes DIR/summary.json."""
    import time

    from corl.errors import CorlError
    from corl.experiments.methods import METHODS, make_method
    from corl.learner import cost_of
    from corl.tasks.registry import load_task
    from corl.versions import library_versions

    if method not in METHODS:
        _fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    try:
        the_task = load_task(task, seed=seed)
        learner = make_method(method, the_task, seed=seed)
    except CorlError as exc:
        _fail(str(exc))
    t0 = time.perf_counter()

    def echo(p, o):
        if not quiet:
            r = "-" if o.return_ is None else f"{o.return_:+.4f}"
            typer.echo(f"trial {p.index:4d}  round {p.round}  {p.step:14s} theta={p.theta.round(4).tolist()} "
                       f"{'success' if o.success else 'FAILURE'}  R={r}", err=True)

    try:
        best = learner.run(callback=echo)
    except CorlError as exc:
        _fail(str(exc))
    history = learner.history
    J_first = history[0][1] if history else None
    payload = {
        "task": the_task.name, "method": method, "seed": seed,
        "success": best is not None,
        "best_theta": None if best is None else best.theta.tolist(),
        "best_return": None if best is None else best.return_,
        "J_initial": cost_of(the_task, history[0][0].w) if J_first is not None else None,
        "J_final": None if best is None else best.J,
        "trials": len(history),
        "failures": sum(not o.success for _, o in history),
        "seconds": time.perf_counter() - t0,
        "versions": library_versions(),
    }
    _write_json(out / "summary.json", payload)
    typer.echo(json.dumps({k: v for k, v in payload.items() if k != "versions"}, indent=2))


def main() -> None:
    app()


if __name__ == "__main__":
    sys.exit(main())
