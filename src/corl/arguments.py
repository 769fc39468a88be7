"""Command-line arguments checked before a command does anything, and nothing left by a refusal.

Every ``corl`` command checks all its arguments before the first rollout and before it creates a
file or folder; a bad one is an :class:`corl.errors.InputError`, which the CLI prints as one line
``error: ...`` and exits with code 2. When a command is refused later (a task that cannot be
built, a store another process writes), :data:`NEW_PATHS` removes what the command created while
it is still empty: a store without a run, an empty output folder.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any, Callable

from corl.errors import CorlError, InputError

__all__ = ["check", "plain_number", "plain_numbers", "NewPaths", "NEW_PATHS", "latest_run", "MAX_STARTS"]

MAX_STARTS = 100_000  # `corl bench synthetic --starts`: 8 methods x 100 take ~2 min on 2 cores, 10^5 ~1.5 days


def check(**args: tuple[str, Any]) -> None:
    """Check arguments by kind; raise :class:`InputError` for the first bad one.

    Keys name the kind of check (a trailing ``_2`` lets a kind repeat), values are
    ``(flag, value)``; None values are not checked. Kinds: ``seed`` (an integer in [0, 2^63)),
    ``jobs`` (-1 or >= 1 workers), ``starts`` (random starts, in [1, MAX_STARTS]), ``rate`` (Hz,
    finite, in (0, MAX_RATE_HZ]), ``task`` (a built-in name or ``package.module:factory``, not
    imported here), ``path`` (a usable path), ``folder`` (an output folder that is one or can be
    created), ``store`` (a store file to write), ``export`` (a ``.csv``/``.parquet`` file to write).
    """
    for kind, (flag, value) in args.items():
        if value is not None:
            _CHECKS[kind.rstrip("_0123456789")](flag, value)


def _seed(flag: str, value: int) -> None:
    if not 0 <= value < 2**63:
        raise InputError(f"{flag} must be an integer in [0, 2^63), got {value}")


def _jobs(flag: str, value: int) -> None:
    if value != -1 and value < 1:
        raise InputError(f"{flag} must be a number of workers >= 1, or -1 for all cores; got {value}")


def _starts(flag: str, value: int) -> None:
    if not 1 <= value <= MAX_STARTS:
        raise InputError(f"{flag} must be a number of starts in [1, {MAX_STARTS}], got {value}")


def _rate(flag: str, value: float) -> None:
    from corl.session import check_rate

    check_rate(value)


def _task(flag: str, value: str) -> None:
    from corl.tasks.registry import check_task_spec

    check_task_spec(value)


def _path(flag: str, path: Path) -> None:
    if "\x00" in str(path) or not str(path).strip():
        raise InputError(f"{flag} {str(path)!r} is not a usable path")


def _folder(flag: str, path: Path) -> None:
    """An output folder: a folder already, or creatable below its nearest existing parent."""
    _path(flag, path)
    if path.exists():
        if not path.is_dir():
            raise InputError(f"{flag} {path} is a file; give a folder (it is created when missing)")
        if not os.access(path, os.W_OK | os.X_OK):
            raise InputError(f"{flag} {path} is not a writable folder; choose another one")
        return
    parent = next((p for p in path.parents if p.exists()), Path("."))
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"{flag} {path} cannot be created: {parent} is not a writable folder")


def _store(flag: str, path: Path) -> None:
    _path(flag, path)
    if path.is_dir():
        raise InputError(f"{flag} {path} is a folder; give the store file, e.g. {path / 'run.corl'}")
    _folder(f"{flag} (its folder)", path.parent)


def _export(flag: str, path: Path) -> None:
    from corl.store.export import check_export_path

    _path(flag, path)
    check_export_path(path)


_CHECKS: dict[str, Callable[[str, Any], None]] = {
    "path": _path, "seed": _seed, "jobs": _jobs, "starts": _starts, "rate": _rate, "task": _task, "folder": _folder,
    "store": _store, "export": _export,
}


_PLAIN_NUMBER = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")  # ASCII digits only


def plain_number(flag: str, text: str) -> float:
    """``text`` as a finite float, or :class:`InputError`: only plain decimal notation such as ``-0.25``
    or ``1.5e3``, not what else Python's ``float()`` takes (``1_000``, ``nan``, ``inf``, non-ASCII digits)."""
    stripped = text.strip()
    if _PLAIN_NUMBER.fullmatch(stripped) is None:
        raise InputError(f"{flag} must be a plain finite number such as 0.25 or -1.5e3, got {text!r}")
    value = float(stripped)
    if not math.isfinite(value):  # e.g. 1e999
        raise InputError(f"{flag} must be finite, got {text!r}")
    return value


def plain_numbers(flag: str, text: str) -> list[float]:
    """Comma-separated :func:`plain_number` s (``--context 0.02,-0.01,0,0.1``), or :class:`InputError`:
    an empty text or an empty item (``0.1,,0.2``) too; the count is the caller's to check."""
    items = text.split(",")
    if not text.strip() or any(not item.strip() for item in items):
        raise InputError(f"{flag} must be comma-separated plain finite numbers such as 0.02,-0.01, got {text!r}")
    return [plain_number(flag if len(items) == 1 else f"{flag} (number {i + 1})", item)
            for i, item in enumerate(items)]


class NewPaths:
    """The paths a running command may create that did not exist when it started."""

    def __init__(self) -> None:
        self.paths: list[Path] = []

    def track(self, *paths: Path) -> None:
        """Forget earlier paths; note which of ``paths`` and their parent folders do not exist yet."""
        self.paths = []
        for path in paths:
            self.paths += [p for p in (path, *path.parents) if not p.exists() and p not in self.paths]

    def remove_if_empty(self) -> None:
        """Remove what was created of the tracked paths while still empty (deepest first):
        a folder with nothing in it, a store that holds no run (with its -wal/-shm files)."""
        from corl.store import RunStore

        for path in sorted(self.paths, key=lambda p: len(p.parts), reverse=True):
            try:
                if path.is_dir():
                    path.rmdir()  # only when empty
                elif path.is_file():
                    with RunStore(path, readonly=True) as db:
                        holds_a_run = bool(db.runs())
                    if not holds_a_run:
                        for suffix in ("", "-wal", "-shm", "-journal"):
                            Path(str(path) + suffix).unlink(missing_ok=True)
            except (OSError, CorlError):
                pass
        self.paths = []


NEW_PATHS = NewPaths()


def latest_run(path: Path):
    """The latest :class:`corl.store.RunInfo` of the store at ``path``, read-only; None without a store or run
    (:func:`corl.store.latest_run`, imported here only when called: this module stays light)."""
    from corl.store import latest_run as latest

    return latest(path)
