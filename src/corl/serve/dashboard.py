"""What the dashboard of ``corl serve`` shows beyond the JSON: figures and the video of the last trial.

:class:`Figures` draws the figures ``corl report`` draws (:func:`corl.experiments.figures.plot_trials`,
:func:`~corl.experiments.figures.plot_return_map`) only while a dashboard is open (``GET /events``
has a subscriber), at most once a second: a copy of the data is taken on the learner's thread
between two calls, and the drawing (matplotlib and the return map's GP fits) happens in a process
of its own at low priority (:mod:`corl.serve.render`), so it never holds the learner's interpreter
lock. Trials told while a figure is drawn are drawn once, together, afterwards.

:class:`Video`, for a task with ``render_comparison(w_demo, w, path)`` (the door), renders the
demonstration beside the last told trial in a separate process at low priority
(:mod:`corl.serve.render`), which loads the task itself from the server's command line: the
learner's task object is never touched by it.
"""

from __future__ import annotations

import contextlib
import json
import os
import pickle
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

__all__ = ["Figures", "Video", "MIN_REDRAW_S"]

MIN_REDRAW_S = 1.0  # at most one redraw a second: trials told meanwhile are drawn together


class Figures:
    """PNG bytes of the dashboard's figures (``trials``, ``return_map``), redrawn on :meth:`want`."""

    def __init__(self) -> None:
        self.png: dict[str, bytes] = {}
        self.notes: dict[str, str] = {}
        self.version = 0  # grows with every redraw
        self.notify = lambda: None
        self._drawn_for = -1
        self._want = threading.Event()
        self._stopping = False
        self._thread: threading.Thread | None = None
        self._proc: subprocess.Popen | None = None
        self.run = None

    def start(self, run) -> None:
        self.run = run
        self._thread = threading.Thread(target=self._loop, name="corl-figures", daemon=True)
        self._thread.start()

    def want(self) -> None:
        """Redraw when the run changed since the last drawing."""
        self._want.set()

    def stop(self) -> None:
        self._stopping = True
        self._want.set()

    def describe(self) -> dict:
        return {"version": self.version, "figures": sorted(self.png), "notes": dict(self.notes)}

    def _loop(self) -> None:
        while True:
            self._want.wait()
            self._want.clear()
            if self._stopping:
                break
            if self.run.version == self._drawn_for:
                continue
            t0 = time.monotonic()
            try:
                self._draw()
            except (OSError, ValueError, EOFError) as exc:  # the drawing process died: a note, and a new one next time
                self._close()
                self.notes = {"trials": f"the figures could not be drawn ({type(exc).__name__}: {exc})"}
                self._drawn_for = self.run.version
            self.version += 1
            self.notify()
            time.sleep(max(0.0, MIN_REDRAW_S - (time.monotonic() - t0)))  # changes meanwhile: drawn together
        self._close()

    def _draw(self) -> None:
        run = self.run
        version, records, J, data, labels = run.executor.submit(run.snapshot).result()  # copies, drawn elsewhere
        if self._proc is None:
            self._proc = _start_render("--figures")
        with tempfile.TemporaryDirectory(prefix="corl-figures-") as tmp:
            job = pickle.dumps({"records": records, "J": J, "data": data, "labels": labels, "folder": tmp})
            self._proc.stdin.write(len(job).to_bytes(8, "little") + job)
            self._proc.stdin.flush()
            line = self._proc.stdout.readline()
            if not line:
                raise OSError("the drawing process ended")
            answer = json.loads(line)
            png = {name: Path(path).read_bytes() for name, path in answer["files"].items()}
        self.png, self.notes, self._drawn_for = png, answer["notes"], version

    def _close(self) -> None:
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait()
            self._proc = None


def _start_render(*args: str) -> subprocess.Popen:
    """``python -m corl.serve.render ARGS`` at low priority, its stdin and stdout piped (binary)."""
    return subprocess.Popen([sys.executable, "-m", "corl.serve.render", *args], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)


class Video:
    """The demonstration beside the last told trial, rendered by ``python -m corl.serve.render`` (one at a time;
    while one renders, only the newest trial waits). ``path`` is the latest video, ``note`` why there is none."""

    def __init__(self, task_spec: str, seed: int) -> None:
        self.task_spec, self.seed = task_spec, seed
        self.path: str | None = None
        self.trial: int | None = None
        self.note = "rendering starts with the first told trial"
        self.version = 0
        self.notify = lambda: None
        self._folder = tempfile.TemporaryDirectory(prefix="corl-video-")
        self._job: tuple | None = None
        self._wake = threading.Condition()
        self._stopping = False
        self._proc = None
        self._thread = threading.Thread(target=self._loop, name="corl-video", daemon=True)
        self._thread.start()

    def want(self, run) -> None:
        """Render the demonstration beside the last told trial of ``run`` (the newest wins)."""
        job = run.last_told()
        if job is not None:
            with self._wake:
                self._job = job
                self._wake.notify()

    def describe(self) -> dict:
        return {"version": self.version, "trial": self.trial, "available": self.path is not None, "note": self.note}

    def stop(self) -> None:
        with self._wake:
            self._stopping = True
            self._wake.notify()
        if self._proc is not None:
            self._proc.kill()
            self._proc.wait()
        self._thread.join(5)
        self._folder.cleanup()

    def _loop(self) -> None:
        while True:
            with self._wake:
                while self._job is None and not self._stopping:
                    self._wake.wait()
                if self._stopping:
                    return
                (index, w_demo, w), self._job = self._job, None
            target = os.path.join(self._folder.name, f"trial_{index:04d}.mp4")
            try:
                answer = self._render(index, w_demo, w, target)
            except (OSError, ValueError) as exc:  # the render process died (killed, out of memory)
                self._proc = None
                answer = {"error": f"the video process ended ({type(exc).__name__}: {exc})"}
            if self._stopping:
                return
            if "path" in answer:
                old, self.path, self.trial, self.note = self.path, answer["path"], index, ""
                if old and old != self.path:
                    with contextlib.suppress(OSError):
                        os.unlink(old)
            else:
                self.note = f"no video: {answer['error']}"
            self.version += 1
            self.notify()

    def _render(self, index: int, w_demo, w, target: str) -> dict:
        if self._proc is None:
            self._proc = _start_render(self.task_spec, str(self.seed))
        job = {"trial": index, "w_demo": np.asarray(w_demo).tolist(), "w": np.asarray(w).tolist(), "path": target}
        self._proc.stdin.write(json.dumps(job).encode() + b"\n")
        self._proc.stdin.flush()
        line = self._proc.stdout.readline()
        if not line:
            raise OSError("no answer")
        return json.loads(line)
