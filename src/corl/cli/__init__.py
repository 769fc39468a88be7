"""The ``corl`` command line: learning runs and benchmarks.

One module per group of commands, registered here in the order ``corl --help`` lists them:
:mod:`~corl.cli.bench` (``bench synthetic``, ``bench door``, ``bench contexts``, ``bench parallel``, ``sweep``), :mod:`~corl.cli.learn`
(``run``, ``ask``, ``tell``), :mod:`~corl.cli.serve` (``serve``: the learner over HTTP), :mod:`~corl.cli.skill` (``policy``: a skill learned across contexts)
and :mod:`~corl.cli.store` (``status``, ``runs``, ``export``, ``report``); :mod:`~corl.cli.common`
holds what they share.

Heavy modules (numpy-heavy learners, joblib, matplotlib, MuJoCo) are imported inside the commands
so that ``corl --help`` stays fast.
"""

from __future__ import annotations

import os
import sys

import typer

from corl.cli import bench, learn, serve, skill, store
from corl.cli.common import refuse_exit

__all__ = ["app", "main"]

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="corl: learn a manipulation skill from one demonstration (Englert & Toussaint, RSS 2016).")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks that reproduce the paper's tables.")
app.add_typer(bench_app, name="bench")

for group, name, command in ((bench_app, "synthetic", bench.bench_synthetic), (bench_app, "door", bench.bench_door),
                             (bench_app, "contexts", bench.bench_contexts), (bench_app, "parallel", bench.bench_parallel),
                             (app, "sweep", bench.sweep), (app, "run", learn.run), (app, "ask", learn.ask),
                             (app, "tell", learn.tell), (app, "serve", serve.serve), (app, "policy", skill.policy), (app, "status", store.status),
                             (app, "runs", store.runs), (app, "export", store.export), (app, "report", store.report)):
    group.command(name)(refuse_exit(command))  # a task's sys.exit() is an error, not a silent exit


#: Optional dependencies (pyproject.toml's extras) by the top-level module a command imports.
_EXTRAS = {"uvicorn": "serve", "starlette": "serve", "ray": "ray", "dask": "dask", "distributed": "dask",
           "pyarrow": "parquet", "mkdocs": "docs", "torch": "bench", "botorch": "bench", "casadi": "bench"}


def main() -> None:
    """The ``corl`` entry point: a bug that escapes a command prints one line, not a traceback."""
    try:
        app()
    except Exception as exc:  # not a usage error: every one of those exits 2 with its own message
        if os.environ.get("CORL_DEBUG"):
            raise
        extra = _EXTRAS.get((getattr(exc, "name", None) or "").split(".")[0]) if isinstance(exc, ImportError) else None
        if extra is not None:  # an optional dependency: say which extra brings it
            typer.echo(f"error: this command needs {exc.name}, part of corl's '{extra}' extra: pip install "
                       f"'corl-skills[{extra}]' (in a checkout of corl: pip install -e '.[{extra}]')", err=True)
            sys.exit(2)
        typer.echo(f"error: internal error {type(exc).__name__}: {exc}. This is a bug in corl or in the task; "
                   "set CORL_DEBUG=1 to see the traceback, and please report it", err=True)
        sys.exit(1)
