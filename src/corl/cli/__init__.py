"""The ``corl`` command line: learning runs and benchmarks.

One module per group of commands, registered here in the order ``corl --help`` lists them:
:mod:`~corl.cli.bench` (``bench synthetic``, ``bench door``, ``sweep``), :mod:`~corl.cli.learn`
(``run``, ``ask``, ``tell``) and :mod:`~corl.cli.store` (``status``, ``runs``, ``export``,
``report``); :mod:`~corl.cli.common` holds what they share.

Heavy modules (numpy-heavy learners, joblib, matplotlib, MuJoCo) are imported inside the commands
so that ``corl --help`` stays fast.
"""

from __future__ import annotations

import os
import sys

import typer

from corl.cli import bench, learn, store

__all__ = ["app", "main"]

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="corl: learn a manipulation skill from one demonstration (Englert & Toussaint, RSS 2016).")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks that reproduce the paper's tables.")
app.add_typer(bench_app, name="bench")

bench_app.command("synthetic")(bench.bench_synthetic)
bench_app.command("door")(bench.bench_door)
app.command("sweep")(bench.sweep)
app.command("run")(learn.run)
app.command("ask")(learn.ask)
app.command("tell")(learn.tell)
app.command("status")(store.status)
app.command("runs")(store.runs)
app.command("export")(store.export)
app.command("report")(store.report)


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
