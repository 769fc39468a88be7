"""SIGKILL of ``corl serve`` at random moments during a 200-trial robot loop, each time restarted on the
same store and port: nothing is lost, no trial is committed or executed twice, and the run ends
identical to an uninterrupted one.

The kills are spread over the whole run: one a random 0-0.15 s (a few ask-move-tell cycles) after the
robot has told each of ten trial counts from 5 to 195, so each lands at a random point of a cycle (an
ask being computed or committed, the robot moving, a tell) in every phase of the run, and none is spent
on a server nobody talks to (each restart costs a couple of seconds of start-up)."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from corl.client import Client  # noqa: E402
from corl.session import StoredRun  # noqa: E402
from corl.store import RunStore  # noqa: E402
from corl.tasks.registry import load_task  # noqa: E402

TRIALS = 200


def _env() -> dict:
    import corl

    src = str(Path(corl.__file__).resolve().parents[1])
    return dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=src)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class KillingServer:
    """``corl serve`` on a fixed port, SIGKILLed a random 0-0.15 s after ``told()`` reaches each of ``targets``
    and started again."""

    def __init__(self, store: Path, port: int, seed: int, told, targets) -> None:
        self.store, self.port = store, port
        self.rng = np.random.default_rng(seed)
        self.told, self.targets = told, list(targets)
        self.kills = 0
        self.proc: subprocess.Popen | None = None
        self.stopping = threading.Event()
        self.thread = threading.Thread(target=self._loop, daemon=True)

    def _start(self) -> None:
        cmd = [sys.executable, "-m", "corl.cli", "serve", "--store", str(self.store), "--task", "synthetic",
               "--port", str(self.port)]
        self.proc = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()  # it listens
        assert line and json.loads(line)["url"].endswith(f":{self.port}"), self.proc.stderr.read()

    def _loop(self) -> None:
        self._start()
        for target in self.targets:
            while self.told() < target:
                if self.stopping.wait(0.005):
                    return
            if self.stopping.wait(self.rng.uniform(0.0, 0.15)):
                return
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait()
            self.kills += 1
            self._start()

    def __enter__(self) -> "KillingServer":
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stopping.set()
        self.thread.join(60)
        if self.proc is not None:
            self.proc.terminate()
            self.proc.wait(30)


@pytest.mark.slow
def test_sigkill_at_random_moments_loses_nothing_and_repeats_nothing(tmp_path):
    task = load_task("synthetic")
    with RunStore(tmp_path / "reference.corl") as db:
        StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=0).run(task, max_trials=TRIALS)
        reference = db.trials(1)
    port = _free_port()
    executed: list[int] = []  # the trials the "robot" ran
    told = [0]
    targets = np.linspace(5, TRIALS - 5, 10).round().astype(int)  # 5, 26, ..., 195: every phase of the run
    with KillingServer(tmp_path / "served.corl", port, seed=24, told=lambda: told[0], targets=targets) as server:
        c = Client(f"http://127.0.0.1:{port}", raw=True, retry_for=120)
        while told[0] < TRIALS:
            trial = c.ask()
            executed.append(trial.index)
            time.sleep(0.02)  # the robot moves
            told[0] = c.tell(task.rollout(trial.w))["trials"]
        kills = server.kills
    assert kills >= 8, f"only {kills} kills: the test did not test much"
    assert executed == list(range(TRIALS)), "a trial was executed twice or skipped"
    with RunStore(tmp_path / "served.corl", readonly=True) as db:
        served = db.trials(1)
        runs = db.runs()
    assert len(runs) == 1 and len(served) == TRIALS and all(r.outcome is not None for r in served)
    for a, b in zip(served, reference):
        assert a.index == b.index and a.proposal.step == b.proposal.step
        assert np.array_equal(a.proposal.w, b.proposal.w) and np.array_equal(a.proposal.theta, b.proposal.theta)
        assert (a.outcome.success, a.outcome.return_) == (b.outcome.success, b.outcome.return_)
    print(f"{kills} SIGKILLs over {TRIALS} trials; the served run equals the uninterrupted one")
