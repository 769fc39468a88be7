"""A simulated task's rollouts in a worker process, so that the learner keeps the GIL meanwhile.

A task opts in with a class attribute ``rollout_in_worker = True``: a simulator whose rollout is a
pure function of ``w`` that changes nothing the learner reads, like the MuJoCo door (a real robot's
task must never opt in: it would be forked). :meth:`corl.session.StoredRun.run`
then forks one :class:`RolloutWorker` after the task is built, sends it ``w`` and receives the
:class:`~corl.problem.Outcome`, while the learner computes the next step-1 or phase candidate in a
thread (:meth:`corl.learner.CORL._speculate`). The child rolls out its fork's copy of the task, so
nothing it does reaches the parent but the outcome.

* an exception in the child comes back as an exception of the same type and message (the same
  one-line error as a rollout in the parent);
* a child that dies, or answers nothing within ``timeout`` seconds, raises :class:`WorkerError`;
* :meth:`RolloutWorker.close` (a context manager) ends the child on every exit path.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import signal
import sys
from multiprocessing.connection import wait

import numpy as np

__all__ = ["RolloutWorker", "WorkerError", "wants_worker"]


class WorkerError(RuntimeError):
    """The rollout worker process died or did not answer."""


def wants_worker(task) -> bool:
    """True when ``task`` opts in to rollouts in a worker process, this is Linux (fork without exec is
    unsafe on macOS once numpy's BLAS runs, and only Linux kills the child with its parent) and this
    process may have children (a daemonic one, e.g. a pool's worker, may not)."""
    return (getattr(task, "rollout_in_worker", False) is True and sys.platform.startswith("linux")
            and "fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon)


def _serve(task, conn, parent_end, parent: int) -> None:
    """The child: w in, pickled ("ok", Outcome), ("error", exc) or ("text", (name, message)) out; None ends."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it ends this process
    parent_end.close()  # so that the parent's death is an EOF here (the fork copied its end of the pipe)
    _die_with_parent(parent)  # the fork also copied the parent's open files (the run store's writer lock)
    while True:
        try:
            w = conn.recv()
        except EOFError:
            return
        if w is None:
            return
        try:
            reply = ("ok", task.rollout(w))
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - every error goes back to the parent
            reply = ("error", exc)
        try:
            data = pickle.dumps(reply)
            back = pickle.loads(data)[1]  # an exception that does not come back the same goes as text
            if reply[0] == "error" and (type(back) is not type(reply[1]) or str(back) != str(reply[1])):
                raise TypeError("the exception does not survive pickling")
        except Exception as exc:  # noqa: BLE001
            bad = reply[1] if reply[0] == "error" else exc
            data = pickle.dumps(("text", (type(bad).__name__, str(bad))))
        try:
            conn.send_bytes(data)
        except OSError:  # the parent is gone
            return


def _die_with_parent(parent: int) -> None:
    """Linux: SIGKILL this process when the parent dies, even in the middle of a rollout."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the EOF on the pipe ends the child after its rollout
        pass
    if os.getppid() != parent:  # the parent died before prctl
        os._exit(0)


def _rebuilt(name: str, message: str) -> Exception:
    """An exception of class name ``name`` and message ``message`` (one the child could not send)."""
    return type(name, (Exception,), {})(message)


class RolloutWorker:
    """One forked process that runs ``task.rollout(w)``; :meth:`rollout` is a drop-in for it."""

    def __init__(self, task, *, timeout: float = 600.0) -> None:
        self.timeout = float(timeout)
        ctx = multiprocessing.get_context("fork")
        self._conn, child = ctx.Pipe()
        self._process = ctx.Process(target=_serve, args=(task, child, self._conn, os.getpid()), name="corl-rollout",
                                    daemon=True)
        self._process.start()
        child.close()
        self._broken: str | None = None

    @property
    def pid(self) -> int | None:
        return self._process.pid

    def rollout(self, w: np.ndarray):
        """The child's ``task.rollout(w)``: its Outcome, or its exception raised here (WorkerError
        when the child died or took longer than ``timeout``). Waiting releases the GIL."""
        if self._broken is not None:
            raise WorkerError(self._broken)
        try:
            self._conn.send(np.asarray(w))
        except (OSError, ValueError):
            self._fail("the rollout worker process is gone (its pipe is closed)")
        try:
            ready = wait([self._conn, self._process.sentinel], timeout=self.timeout)
        except BaseException:  # e.g. Ctrl-C: the child's answer would stay in the pipe for the next w
            self._broken = "a rollout was interrupted; make a new RolloutWorker"
            self.close()
            raise
        if self._conn in ready:
            try:
                kind, value = pickle.loads(self._conn.recv_bytes())
            except (EOFError, OSError):  # the child ended: its pipe closed
                self._died()
            if kind == "error":
                raise value
            if kind == "text":
                raise _rebuilt(*value)
            return value
        if ready:  # only the sentinel: the child ended
            self._died()
        self._fail(f"the rollout worker process (pid {self.pid}) did not answer within {self.timeout:g} s")

    def _died(self):
        self._process.join(1.0)
        code = self._process.exitcode
        self._fail(f"the rollout worker process (pid {self.pid}) died (exit code {code}) during a rollout"
                   if code is not None else
                   f"the rollout worker process (pid {self.pid}) closed its pipe during a rollout")

    def _fail(self, message: str):
        self._broken = message
        self.close()
        raise WorkerError(message)

    def close(self) -> None:
        """End the child (asked, then terminated, then killed) and close the pipe; safe to call twice."""
        process = self._process
        if process.is_alive():
            try:
                self._conn.send(None)
            except (OSError, ValueError):
                pass
            process.join(1.0)
        if process.is_alive():
            process.terminate()
            process.join(1.0)
        if process.is_alive():
            os.kill(process.pid, signal.SIGKILL)
            process.join(1.0)
        self._conn.close()

    def __enter__(self) -> "RolloutWorker":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
