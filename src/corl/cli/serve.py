"""``corl serve``: one process holds the learner beside the robot; clients ask and tell over HTTP.

The task is named here, on the server's command line, and nowhere else: a request can never name
code to import (:mod:`corl.serve`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from corl.arguments import NEW_PATHS
from corl.cli.common import check_args, fail

__all__ = ["serve"]


def serve(
    store: Path = typer.Option(..., help="run store: its latest run goes on, or a new one starts"),
    task: str = typer.Option(..., help="the task: 'synthetic', 'door' or 'package.module:make_task'"),
    method: Optional[str] = typer.Option(None, help="method of a new run (default CORL+PIBU for a built-in task, "
                                                    "CORL for your own); with a run in the store, only its method"),
    seed: Optional[int] = typer.Option(None, help="seed of a new run (default 0); with a run in the store, only "
                                                  "its seed"),
    host: str = typer.Option("127.0.0.1", help="interface to listen on; anything but loopback needs --token-file"),
    port: int = typer.Option(8765, help="TCP port (0: any free port, printed)"),
    token_file: Optional[Path] = typer.Option(None, help="file holding the token every request must send "
                                                         "('Authorization: Bearer <token>'); chmod 600"),
    rate: float = typer.Option(100.0, help="rate of the joint trajectories handed out (Hz)"),
    video: bool = typer.Option(True, "--video/--no-video", help="render the last told trial in the simulator for "
                                                                 "the dashboard (tasks that render)"),
    access_log: bool = typer.Option(False, "--access-log", help="log every request on stderr"),
    robots: Optional[int] = typer.Option(None, "--robots", help="K robots of a new run: up to K trials out at once, "
                                                                 "each robot names itself in its asks (default 1; "
                                                                 "with a run in the store, only its K)"),
) -> None:
    """Serve the learner over HTTP (POST /ask, POST /tell, GET /status, /trials) with a live dashboard at /."""
    from corl.errors import CorlError, MissingExtraError

    check_args(task=("--task", task), seed=("--seed", seed), rate=("--rate", rate), store=("--store", store))
    if not 0 <= port <= 65535:
        fail(f"--port must be in 0..65535, got {port}")
    if robots is not None and not 1 <= robots <= 64:
        fail(f"--robots must be an integer in [1, 64], got {robots}")
    try:
        from corl.serve import check_bind, read_token, serve_forever
    except MissingExtraError as exc:
        fail(str(exc))
    NEW_PATHS.track(store)
    if video:  # before the task imports MuJoCo: an offscreen backend that works (the video process inherits it)
        from corl.mujoco.video import ensure_rendering

        ensure_rendering()  # when none does, the dashboard's video panel says what to install
    try:
        token = None if token_file is None else read_token(token_file)
        check_bind(host, token)
        serve_forever(store, task, method=method, seed=seed, host=host, port=port, token=token, rate=rate,
                      video=video, access_log=access_log, ready=_announce, robots=robots)
    except CorlError as exc:
        fail(str(exc))
    except OSError as exc:
        fail(f"cannot listen on {host}:{port}: {exc.strerror or exc}; choose another --port (0: any free one)")


def _announce(url: str, status: dict) -> None:
    """The first line on stdout: where the server listens (a script reads it; --port 0 picks the port)."""
    typer.echo(json.dumps({"url": url, "run": status["run"], "task": status["task"], "method": status["method"],
                           "trials": status["trials"], "done": status["done"],
                           **({"robots": status["robots"]} if "robots" in status else {})}))
    typer.echo(f"corl serve: run {status['run']} ({status['task']}, {status['method']}), {status['trials']} trials "
               f"told; dashboard and API at {url} - Ctrl-C stops", err=True)
