"""Progress of the long commands (``corl run``, ``corl bench ...``) on stderr.

Every long command reports through one :class:`Tracker`, in one of three modes (:class:`Mode`):

* ``LIVE``  : a rich display on stderr, one row per stage: done / total (``?`` when the budget is
  not known in advance), failures so far, best return so far, elapsed time and a note (the
  default when stderr is a terminal);
* ``LOG``   : one plain line per event on stderr, for log files and CI (``--log``, and the
  default when stderr is not a terminal);
* ``QUIET`` : nothing (``--quiet``); errors are still printed by the command.

stdout is never written here: it carries the command's result (a table, or with ``--json``
exactly one JSON document), so ``corl bench synthetic --json | jq`` works while progress shows.

Glossary
--------
stage    : one row of the display: ``"trials"`` of a run, a method's starts or seeds in a
           benchmark (``"CORL+PIBU"``), ``"safe region"`` (grid points of the door benchmark)
done     : events finished in this stage (trials, starts, seeds, grid points)
total    : events this stage will finish, or None when unknown (a CORL run's trial count)
failures : failed trials so far in this stage (S = 0); None for stages without failures
best     : highest return R of a successful trial so far in this stage; None before one
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from dataclasses import dataclass
from enum import Enum

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["Mode", "choose_mode", "Tracker", "format_return"]


class Mode(Enum):
    """How a :class:`Tracker` shows progress."""

    LIVE = "live"
    LOG = "log"
    QUIET = "quiet"


def choose_mode(*, quiet: bool = False, log: bool = False, console: Console | None = None) -> Mode:
    """``QUIET`` if ``quiet``; ``LOG`` if ``log`` or stderr is not a terminal; else ``LIVE``."""
    if quiet:
        return Mode.QUIET
    if log:
        return Mode.LOG
    console = console or Console(stderr=True)
    return Mode.LIVE if console.is_terminal and not console.is_dumb_terminal else Mode.LOG


def format_return(value: float | None) -> str:
    """A return as the display shows it: ``+0.4512``, or ``-`` for none yet."""
    return "-" if value is None or not math.isfinite(value) else f"{value:+.4f}"


@dataclass
class _Row:
    """The state of one stage (see the glossary)."""

    done: int = 0
    total: int | None = None
    failures: int | None = None
    best: float | None = None
    note: str = ""
    task_id: int | None = None


class Tracker:
    """Progress of one command on stderr; use as a context manager around the work.

    Parameters
    ----------
    mode : how to show progress (see :func:`choose_mode`).
    title : the command, printed in front of every log line (``"run"``, ``"bench door"``).
    console : where to write (default: a rich console on stderr).
    protect_stdout : while entered, send stray ``print`` output (a user's task, a library) to
        stderr, so that a ``--json`` command's stdout holds its JSON document only.
    """

    def __init__(self, mode: Mode, title: str, *, console: Console | None = None,
                 protect_stdout: bool = False) -> None:
        self.mode = mode
        self.title = title
        self.console = console or Console(stderr=True)
        self.protect_stdout = protect_stdout
        self.rows: dict[str, _Row] = {}
        self._t0 = time.perf_counter()
        self._live: Progress | None = None
        self._redirect: contextlib.AbstractContextManager | None = None

    def __enter__(self) -> "Tracker":
        self._t0 = time.perf_counter()
        if self.protect_stdout:
            self._redirect = contextlib.redirect_stdout(sys.stderr)
            self._redirect.__enter__()
        if self.mode is Mode.LIVE:
            self._live = Progress(
                TextColumn("[bold]{task.fields[stage]}"), BarColumn(bar_width=24), MofNCompleteColumn(),
                TextColumn("{task.fields[failures]}"), TextColumn("{task.fields[best]}"), TimeElapsedColumn(),
                TextColumn("{task.description}"), console=self.console)
            self._live.start()
        return self

    def __exit__(self, *exc) -> bool:
        if self._live is not None:
            self._live.stop()
            self._live = None
        if self._redirect is not None:
            self._redirect.__exit__(*exc)
            self._redirect = None
        return False

    @property
    def elapsed(self) -> float:
        """Seconds since the tracker was entered."""
        return time.perf_counter() - self._t0

    def add_stage(self, stage: str, *, total: int | None = None, failures: bool = True) -> None:
        """Show ``stage`` before its first event (its clock starts now); nothing is logged.

        ``failures``: whether the stage counts failures (then it shows ``failures 0`` from the start).
        """
        if stage in self.rows:
            return
        row = self.rows[stage] = _Row(total=total, failures=0 if failures else None)
        if self._live is not None:
            row.task_id = self._live.add_task("", total=total, stage=stage, failures=self._failures_text(row),
                                              best=self._best_text(row))

    def update(self, stage: str, *, done: int | None = None, total: int | None = None, advance: int = 0,
               failures: int | None = None, ret: float | None = None, best: float | None = None,
               note: str = "", line: str | None = None) -> None:
        """Record one event of ``stage`` and show it.

        Parameters
        ----------
        done : events finished so far (absolute); otherwise ``advance`` is added to the count.
        total : the stage's total, when known.
        failures : failures this event adds; None for a stage that does not count failures.
        ret : a successful trial's return; the stage keeps the highest.
        best : the best return so far as the learner sees it (replaces the kept one; a learner's
            best policy need not have the highest return, e.g. a method over ``w`` ranks by R - J).
        note : what just happened, shown at the end of the live row and the log line.
        line : the log line to print in ``LOG`` mode instead of the generated one.
        """
        if stage not in self.rows:
            self.add_stage(stage, total=total, failures=failures is not None)
        row = self.rows[stage]
        row.done = done if done is not None else row.done + advance
        if total is not None:
            row.total = total
        if failures is not None:
            row.failures = (row.failures or 0) + failures
        if best is not None:
            row.best = float(best)
        elif ret is not None and math.isfinite(ret) and (row.best is None or ret > row.best):
            row.best = float(ret)
        row.note = note
        if self._live is not None:
            self._live.update(row.task_id, completed=row.done, total=row.total, description=note,
                              failures=self._failures_text(row), best=self._best_text(row))
        elif self.mode is Mode.LOG:
            self.message(line if line is not None else self.log_line(stage))

    def message(self, text: str) -> None:
        """A line of human text on stderr (above the live display); nothing in ``QUIET`` mode."""
        if self.mode is not Mode.QUIET:
            self.console.print(text, markup=False, highlight=False, soft_wrap=True)

    def log_line(self, stage: str) -> str:
        """The plain one-line state of ``stage``: ``bench synthetic | PoWER 3/8 | failures 2 | ...``."""
        row = self.rows[stage]
        parts = [self.title, f"{stage} {row.done}/{'?' if row.total is None else row.total}"]
        parts += [t for t in (self._failures_text(row), self._best_text(row)) if t]
        parts.append(f"{self.elapsed:.1f} s")
        if row.note:
            parts.append(row.note)
        return " | ".join(parts)

    @staticmethod
    def _failures_text(row: _Row) -> str:
        return "" if row.failures is None else f"failures {row.failures}"

    @staticmethod
    def _best_text(row: _Row) -> str:
        return "" if row.failures is None and row.best is None else f"best R {format_return(row.best)}"
