"""``corl serve --robots K``: K robots ask and tell at once (corl.serve.fleet), against a real server process.

Each robot names itself; its own pending trial is handed back on a re-ask (a restart included: the store
keeps who holds what); a robot asking while nothing can go out gets 503 with ``Retry-After``; any pending
trial may be told in any order; no trial is lost or told twice."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
import urllib.error
import urllib.request
import uuid
from pathlib import Path

import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from cli_refusal import refuse  # noqa: E402
from corl.client import Client, ServerError  # noqa: E402
from corl.errors import InputError, StateError  # noqa: E402
from corl.methods import make_method  # noqa: E402
from corl.serve import background  # noqa: E402
from corl.store import RunStatus, RunStore  # noqa: E402

K = 3

# A synthetic task with a small budget: step 1 rolls out its converged motion only, 30 black-box trials.
MODULE = """
from dataclasses import replace

from corl.settings import PAPER_SYNTHETIC
from corl.tasks.synthetic import SyntheticTask


class FleetTask(SyntheticTask):
    name = "fleet-synthetic"

    def method_settings(self):
        return replace(PAPER_SYNTHETIC, corl=replace(PAPER_SYNTHETIC.corl, rollout_every_step=False,
                                                     max_rl_trials=30))


def make_task():
    return FleetTask()
"""


@pytest.fixture
def module(tmp_path, monkeypatch):
    name = f"fleettask_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(MODULE))
    monkeypatch.syspath_prepend(str(tmp_path))
    return f"{name}:make_task"


class Server:
    """``corl serve --port 0 --robots K`` in a subprocess on loopback; ``url`` once it listens."""

    def __init__(self, store: Path, task: str, *args: str) -> None:
        import corl

        src = str(Path(corl.__file__).resolve().parents[1])
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=os.pathsep.join([src, str(store.parent)]))
        cmd = [sys.executable, "-m", "corl.cli", "serve", "--store", str(store), "--task", task, "--port", "0",
               "--host", "127.0.0.1", "--no-video", *args]
        self.proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.proc.stdout.readline()
        assert line, self.proc.stderr.read()
        self.first = json.loads(line)
        self.url = self.first["url"]

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(30)

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            self.proc.wait(30)
        self.proc.stdout.close()
        self.proc.stderr.close()


def _post(url: str, path: str, body: dict):
    request = urllib.request.Request(url + path, data=json.dumps(body).encode(), method="POST",
                                     headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=30) as r:
            return r.status, {k.lower(): v for k, v in r.headers.items()}, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, {k.lower(): v for k, v in e.headers.items()}, json.loads(e.read())


def _ask(client: Client, robot: str):
    """The robot's trial, None while nothing can go out (503), or "done" once the run hands out no more."""
    try:
        return client.ask(robot=robot)
    except ServerError as exc:
        assert exc.status == 503 and "ask again after a tell" in str(exc), exc
        return None
    except StateError as exc:
        assert "finished" in str(exc) or "hands out no more" in str(exc), exc
        return "done"


def _check_store(store: Path, task_factory) -> list:
    from corl.session import StoredRun

    with RunStore(store, readonly=True) as db:
        (run,) = db.runs()
        records = db.trials(run.id)
        order = db.told_order(run.id)
        assert StoredRun.open(db, task_factory(), run.id).done  # its asks, tells and waits replay exactly
    assert [r.index for r in records] == list(range(len(records)))  # contiguous: none lost
    assert sorted(order) == list(range(len(records))) and all(r.outcome is not None for r in records)  # told once
    assert run.status is RunStatus.FINISHED and run.config["robots"] == K
    task = task_factory()
    corl = make_method("CORL", task, seed=0)
    corl.run()  # one robot, the same budget: the fleet fails at most as test_parallel allows
    assert sum(not r.outcome.success for r in records) <= 1.25 * sum(not o.success for _, o in corl.history) + 1
    return records


def test_three_robots_in_threads_finish_the_run_and_lose_nothing(tmp_path, module):
    from corl.tasks.registry import load_task

    task = load_task(module)
    store = tmp_path / "fleet.corl"
    server = Server(store, module, "--robots", str(K))
    executed: list[int] = []
    most_out = [0]
    errors: list[BaseException] = []
    stop = threading.Event()

    def robot(name: str) -> None:
        try:
            c = Client(server.url, raw=True, robot=name, retry_for=0)
            while True:
                trial = _ask(c, name)
                if trial == "done":
                    return
                if trial is None:
                    time.sleep(0.01)
                    continue
                assert c.ask().index == trial.index  # a re-ask by the same robot: the same trial
                executed.append(trial.index)
                c.tell(task.rollout(trial.w), trial=trial.index)
        except BaseException as exc:  # noqa: BLE001 - reported by the main thread
            errors.append(exc)

    def watch() -> None:
        try:
            c = Client(server.url, retry_for=0)
            while not stop.is_set():
                s = c.status()
                most_out[0] = max(most_out[0], len(s["pending_trials"]))
                assert s["robots"] == K and len(s["pending_trials"]) <= K
                assert s["pending"] == (min(s["pending_trials"]) if s["pending_trials"] else None)
                time.sleep(0.005)
        except BaseException as exc:  # noqa: BLE001 - reported by the main thread
            errors.append(exc)

    try:
        assert server.first["robots"] == K
        threads = [threading.Thread(target=robot, args=(f"arm-{i}",)) for i in range(K)]
        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        for t in threads:
            t.start()
        for t in threads:
            t.join(60)
        stop.set()
        watcher.join(10)
        assert not errors, errors
        status = Client(server.url).status()
        assert status["done"] and status["pending_trials"] == [] and status["pending"] is None
    finally:
        server.stop()
    records = _check_store(store, lambda: load_task(module))
    assert sorted(executed) == list(range(len(records)))  # each trial ran on one robot, once
    assert 2 <= most_out[0] <= K  # the robots did work at once


def test_a_reask_a_fourth_robot_and_a_sigkill_with_trials_out(tmp_path, module):
    from corl.tasks.registry import load_task

    task = load_task(module)
    store = tmp_path / "fleet.corl"
    names = [f"arm-{i}" for i in range(K)]
    held: dict[str, object] = {}
    server = Server(store, module, "--robots", str(K))
    try:
        c = Client(server.url, raw=True, retry_for=0)
        while len(held) < K:  # one trial at a time until the black-box step hands out K
            for name in names:
                if name not in held and (trial := _ask(c, name)) is not None:
                    held[name] = trial
            if len(held) < K:
                name, trial = sorted(held.items(), key=lambda kv: kv[1].index)[0]
                c.tell(task.rollout(trial.w), trial=trial.index)
                del held[name]
        assert {c.ask(robot=n).index for n in names} == {t.index for t in held.values()}  # re-asks: the same
        status, headers, body = _post(server.url, "/ask", {"raw": True, "robot": "arm-9"})
        out = sorted(t.index for t in held.values())
        assert status == 503 and headers["retry-after"] == "1"
        assert body["error"].startswith(f"3 trials are out (trials {out[0]} (robot ")
        assert "ask again after a tell" in body["error"] and "\n" not in body["error"]
        status, _, s = _post(server.url, "/ask", {"raw": True, "robot": "arm 1"})
        assert status == 400 and "'robot' must be a name" in s["error"]
        status, _, s = _post(server.url, "/ask", {"raw": True})
        assert status == 400 and "name yours" in s["error"]
        first = held.pop(names[1])  # told out of order: the middle robot first
        c.tell(task.rollout(first.w), trial=first.index)
        assert c.tell(task.rollout(first.w), trial=first.index)["repeated"] is True
        with pytest.raises(StateError, match="is not pending"):
            c.tell(True, 1.0, trial=first.index + 100)
        server.kill()  # with two trials out
    finally:
        server.stop()
    server = Server(store, module)  # the stored K: no --robots needed
    try:
        c = Client(server.url, raw=True, retry_for=0)
        s = c.status()
        assert s["robots"] == K and s["pending_trials"] == sorted(t.index for t in held.values())
        assert s["pending_robots"] == [n for n, _ in sorted(held.items(), key=lambda kv: kv[1].index)]
        for name, trial in held.items():  # each robot gets its own trial back
            assert c.ask(robot=name).index == trial.index
        for trial in held.values():
            c.tell(task.rollout(trial.w), trial=trial.index)
        while True:  # the run goes on to its end, robots taking turns
            asked = [t for n in names if (t := _ask(c, n)) not in (None, "done")]
            if not asked and _ask(c, names[0]) == "done":
                break
            for trial in asked:
                c.tell(task.rollout(trial.w), trial=trial.index)
        assert c.status()["done"]
    finally:
        server.stop()
    _check_store(store, lambda: load_task(module))


def test_a_mismatching_robots_flag_is_refused_in_one_line(tmp_path, module):
    store = tmp_path / "fleet.corl"
    with background(store, module, robots=K) as url:
        Client(url, raw=True, robot="a").ask()
    refuse(["serve", "--store", str(store), "--task", module, "--port", "0", "--no-video", "--robots", "2"],
           "--robots 2 differs from run 1")
    refuse(["serve", "--store", str(tmp_path / "new.corl"), "--task", module, "--port", "0", "--no-video",
            "--robots", "0"], "--robots must be an integer in [1, 64]")
    with pytest.raises(InputError, match="Client\\(robot\\) must be a name"):
        Client("http://127.0.0.1:1", robot="x" * 65)


def test_one_robot_is_served_as_before_and_a_robot_name_changes_nothing(tmp_path):
    from corl.tasks.registry import load_task

    task = load_task("synthetic")
    with background(tmp_path / "one.corl", "synthetic") as url:
        c = Client(url, raw=True)
        first = c.ask(robot="a")
        assert c.ask(robot="b").index == first.index == 0  # one trial at a time, whoever asks
        c.tell(task.rollout(first.w))
        s = c.status()
        assert s["pending"] is None and "pending_trials" not in s and "robots" not in s


def test_trials_out_that_no_robot_holds_go_to_the_first_robots_that_ask(tmp_path, module):
    from corl.session import StoredRun
    from corl.tasks.registry import load_task

    task = load_task(module)
    store = tmp_path / "run.corl"
    with RunStore(store) as db:  # as corl run --robots 3 leaves a run it was killed in: trials out, no robot named
        session = StoredRun.new(task, task_spec=module, method="CORL", seed=0, robots=K).attach(db)
        while len(session.pending) < 2:
            if session.try_ask() is None:
                oldest = session.pending[0]
                session.tell(task.rollout(oldest.w), oldest.index)
        out = [p.index for p in session.pending]
    with background(store, module) as url:
        c = Client(url, raw=True, retry_for=0)
        assert c.status()["pending_robots"] == [None] * len(out)
        assert [c.ask(robot=name).index for name in ("x", "y")] == out[:2]
        assert c.ask(robot="x").index == out[0] and c.status()["pending_robots"][:2] == ["x", "y"]
