"""What the commands of ``corl`` share: the one-line error, the argument checks, JSON output, the
progress display and the options of the long commands."""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Callable, Optional

import typer

from corl.arguments import NEW_PATHS, check  # light: no numpy
from corl.errors import CorlError

__all__ = ["fail", "check_args", "refuse_exit", "make_folder", "method_list", "write_json", "progress_tracker",
           "print_json", "open_store", "QUIET", "JSON_OUT", "LOG", "BACKEND", "ADDRESS"]


def fail(message: str, code: int = 2) -> None:
    """Print ``error: message`` and exit; what the command created is removed while still empty."""
    typer.echo(f"error: {message}", err=True)
    NEW_PATHS.remove_if_empty()
    raise typer.Exit(code)


def check_args(**args) -> None:
    """:func:`corl.arguments.check` of the arguments, before any rollout or file; the first bad one exits 2."""
    try:
        check(**args)
    except CorlError as exc:
        fail(str(exc))


def refuse_exit(command: Callable) -> Callable:
    """``command``, with a ``sys.exit()`` inside it turned into a one-line error, exit 2.

    corl's own refusals raise ``typer.Exit``, never :class:`SystemExit`, so a SystemExit that reaches
    here came from user code (a task's module, factory, rollout or reference): it must not end the
    command silently with that code, as if the command had succeeded.
    """

    @functools.wraps(command)
    def guarded(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except SystemExit as exc:
            fail(f"the task's code called sys.exit({exc.code!r}) {_where(exc)}; a task must raise an exception "
                 "instead (an exit would end corl as if the command had succeeded): fix the task. What corl "
                 "committed before that call is kept")

    return guarded


def _where(exc: BaseException) -> str:
    """``in FUNCTION (FILE:LINE)``: the innermost frame of ``exc``'s traceback, the one that raised it."""
    tb = exc.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    if tb is None:
        return ""
    code = tb.tb_frame.f_code
    return f"in {code.co_name} ({Path(code.co_filename).name}:{tb.tb_lineno})"


def make_folder(flag: str, path: Path) -> None:
    """Create the output folder ``path`` now, before the long work, and write a file in it (removed at once):
    a place where nothing can be created or written (read-only, or refused even to root, as /proc and /sys
    are) exits 2 at once. ``NEW_PATHS`` removes the folder again on a refusal."""
    import tempfile

    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fail(f"{flag} {path} cannot be created: {exc.strerror}; choose another {flag}")
    try:
        tempfile.TemporaryFile(dir=path).close()
    except OSError as exc:
        fail(f"{flag} {path} cannot be written: {exc.strerror}; choose another {flag}")


def method_list(methods: Optional[str], *, default: list[str], allowed) -> list[str]:
    """Comma-separated method names, checked against ``allowed``; ``default`` when None."""
    names = default if methods is None else [m.strip() for m in methods.split(",") if m.strip()]
    if not names:
        fail(f"--methods {methods!r} names no method; give comma-separated names from {', '.join(allowed)}, "
             "or drop --methods for the default ones")
    unknown = [m for m in names if m not in allowed]
    if unknown:
        fail(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(allowed)}")
    return names


def write_json(path: Path, payload: dict) -> None:
    """Write ``payload`` whole or not at all (:func:`corl.store.files.write_atomically`); a full disk exits 2."""
    from corl.store.files import write_text_atomically

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_text_atomically(path, json.dumps(payload, indent=2, sort_keys=False) + "\n")
    except OSError as exc:
        fail(f"cannot create the folder of {path}: {exc.strerror}; choose another --out")
    except CorlError as exc:
        fail(str(exc))


# Output options of the long commands (corl.progress): progress on stderr, the result on stdout.
QUIET = typer.Option(False, "--quiet", "-q", help="nothing on stderr but errors")
JSON_OUT = typer.Option(False, "--json", help="stdout: one JSON document and nothing else")
LOG = typer.Option(False, "--log", help="plain progress lines, not the live display (default if stderr is no terminal)")


def progress_tracker(title: str, *, quiet: bool, log: bool, json_out: bool):
    """The command's :class:`corl.progress.Tracker`; with ``--json`` stray prints go to stderr."""
    from corl.progress import Tracker, choose_mode

    return Tracker(choose_mode(quiet=quiet, log=log), title, protect_stdout=json_out)


def print_json(payload: dict) -> None:
    typer.echo(json.dumps(payload, indent=2))


# Where the runs of a benchmark go (corl.experiments.backends).
BACKEND = typer.Option("loky", help="where runs execute: loky (local processes), ray or dask (a cluster)")
ADDRESS = typer.Option(None, help="a running Ray (auto, HOST:PORT) or Dask (tcp://HOST:8786) cluster to use; "
                                  "default: start a local one with --jobs workers")


def open_store(path: Path, *, readonly: bool = False, create: bool = True):
    from corl.store import RunStore

    if not readonly and create:
        path.parent.mkdir(parents=True, exist_ok=True)
    return RunStore(path, readonly=readonly, create=create and not readonly)

