"""The ask/tell API of ``corl serve`` through :class:`corl.client.Client`, against a server in a thread
(:func:`corl.serve.background`): a served run is the local run, trial for trial; both calls are
idempotent; the store holds every answer before the client sees it."""

from __future__ import annotations

import json
import urllib.request

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from corl.client import Client, ServerError  # noqa: E402
from corl.errors import InputError, StateError  # noqa: E402
from corl.serve import background  # noqa: E402
from corl.session import StoredRun  # noqa: E402
from corl.store import RunStore, StoreError  # noqa: E402
from corl.tasks.registry import load_task  # noqa: E402


def _get(url: str, path: str):
    with urllib.request.urlopen(url + path, timeout=30) as r:
        return r.status, dict(r.headers), json.loads(r.read())


def test_a_served_run_is_the_local_run_trial_for_trial(tmp_path):
    task = load_task("synthetic", seed=1)
    with RunStore(tmp_path / "local.corl") as db:
        StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=1).run(task, max_trials=40)
        local = db.trials(1)
    with background(tmp_path / "served.corl", "synthetic", seed=1) as url:
        c = Client(url, raw=True)
        for _ in range(40):
            trial = c.ask()
            assert trial.q is None and trial.w is not None  # raw: w, no trajectory
            c.tell(task.rollout(trial.w))
        status = c.status()
    with RunStore(tmp_path / "served.corl", readonly=True) as db:
        served = db.trials(1)
    assert len(served) == len(local) == 40 and status["trials"] == 40
    for a, b in zip(served, local):
        assert np.array_equal(a.proposal.w, b.proposal.w) and a.proposal.step == b.proposal.step
        assert (a.outcome.success, a.outcome.return_) == (b.outcome.success, b.outcome.return_)
    assert status["failures"] == sum(not r.outcome.success for r in local)


def test_ask_and_tell_are_idempotent_and_conflicts_are_409(tmp_path):
    task = load_task("synthetic")
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        first = c.ask()
        again = c.ask()  # nothing told: the same trial, not a new one
        assert again.index == first.index == 0 and np.array_equal(again.w, first.w)
        with pytest.raises(StateError, match="trial 3 is not pending"):
            c.tell(True, 1.0, trial=3)
        outcome = task.rollout(first.w)
        answer = c.tell(outcome)
        assert answer["trials"] == 1 and "repeated" not in answer
        repeated = c.tell(outcome)  # a retry after a lost answer: answered again, nothing stored twice
        assert repeated["repeated"] is True and repeated["trials"] == 1
        with pytest.raises(StateError, match="already told"):
            c.tell(False, trial=0)
        with pytest.raises(StateError, match="no trial is pending"):
            c.tell(False, trial=1)
        with pytest.raises(InputError, match="finite return"):
            c.tell(True, None, trial=0)
        second = c.ask()
        assert second.index == 1
        status, headers, body = _get(url, "/status")
        assert body["pending"] == 1 and body["trials"] == 1
        request = urllib.request.Request(url + "/ask", data=b'{"raw": true}', method="POST",
                                         headers={"Content-Type": "application/json"})
        with urllib.request.urlopen(request, timeout=30) as r:
            assert json.loads(r.read())["trial"] == 1
            assert r.headers["Server-Timing"].startswith("compute;dur=")
    with RunStore(tmp_path / "s.corl", readonly=True) as db:  # committed: trial 0 told once, trial 1 pending
        records = db.trials(1)
    assert [r.outcome is not None for r in records] == [True, False]


def test_a_demonstration_that_fails_twice_is_refused_and_the_second_reading_is_not_stored(tmp_path):
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        first = c.ask()
        c.tell(False)  # a failed reading may be wrong: stored, and the demonstration is asked again (twice)
        again = c.ask()
        assert again.index == 1 and np.array_equal(again.w, first.w)
        c.tell(False)
        assert c.ask().index == 2
        with pytest.raises(InputError, match="demonstration failed"):  # HTTP 400
            c.tell(False)
        assert c.status()["pending"] == 2 and c.status()["trials"] == 2


def test_a_task_without_reference_needs_raw_and_a_task_with_one_gets_its_trajectory(tmp_path):
    with background(tmp_path / "s.corl", "synthetic") as url:
        with pytest.raises(InputError, match=r'ask with \{"raw": true\}'):
            Client(url).ask()
        assert Client(url).status()["pending"] is None  # refused before a trial was handed out
    with background(tmp_path / "p.corl", "examples.panda_switch:make_task") as url:
        trial = Client(url).ask()
        assert trial.w is None and trial.t.ndim == 1 and trial.q.shape == (trial.t.size, len(trial.joint_names))
        assert np.all(np.diff(trial.t) > 0) and np.isfinite(trial.q).all()


def test_a_restarted_server_goes_on_where_the_store_stopped(tmp_path):
    task = load_task("synthetic")
    store = tmp_path / "s.corl"
    with background(store, "synthetic") as url:
        c = Client(url, raw=True)
        for _ in range(5):
            c.tell(task.rollout(c.ask().w))
        pending = c.ask()
    with background(store, "synthetic") as url:  # the pending trial is handed out again, not a new one
        c = Client(url, raw=True)
        assert c.status()["trials"] == 5
        again = c.ask()
        assert again.index == pending.index and np.array_equal(again.w, pending.w)
        with pytest.raises(StoreError, match="already open for writing"):  # one server holds a store
            with background(store, "synthetic"):
                pass
    with pytest.raises(InputError, match="--seed 4 differs"):
        with background(store, "synthetic", seed=4):
            pass


def test_status_trials_and_best_speak_like_a_learner(tmp_path):
    task = load_task("synthetic")
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        assert c.best is None and c.done is False and c.stop_reason is None
        while not c.done:
            trial = c.ask()
            c.tell(task.rollout(trial.w))
        rows = c.trials()
        assert c.stop_reason in ("converged", "budget", "max_rounds", "no_improvement")
        best = c.best
        told = [r for r in rows if r["success"]]
        assert best.return_ == max(r["return"] for r in told)
        assert len(c.trials(since=len(rows) - 3)) == 3
        with pytest.raises(StateError, match="has finished"):
            c.ask()


def test_an_unreachable_server_is_one_clear_error(tmp_path):
    c = Client("http://127.0.0.1:9", retry_for=0.2)
    with pytest.raises(ServerError, match="cannot reach the corl server"):
        c.ask()
    with pytest.raises(InputError, match="url must look like"):
        Client("127.0.0.1:8765")


@pytest.mark.slow
def test_the_robot_client_example_learns_what_a_local_run_learns(tmp_path, capsys):
    """examples/robot_client.py: a simulated Panda follows the served joint trajectories (500 Hz)."""
    from examples import robot_client
    from examples.panda_switch import make_task

    task = make_task()
    with RunStore(tmp_path / "local.corl") as db:
        local = StoredRun.start(db, task, task_spec="examples.panda_switch:make_task", method="CORL", seed=0)
        local.run(task)
        expected = db.trials(1)
    with background(tmp_path / "served.corl", "examples.panda_switch:make_task", rate=500) as url:
        robot_client.main(url)
    with RunStore(tmp_path / "served.corl", readonly=True) as db:
        served = db.trials(1)
    assert len(served) == len(expected) > 10
    assert [(r.outcome.success, r.outcome.return_) for r in served] == \
        [(r.outcome.success, r.outcome.return_) for r in expected]
    assert f"return {local.best.return_:.4f}" in capsys.readouterr().out


def test_a_learner_that_raises_after_the_commit_stops_the_server_visibly(tmp_path, monkeypatch):
    from corl.learner import CORL

    task = load_task("synthetic")
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        c.tell(task.rollout(c.ask().w))
        trial = c.ask()
        monkeypatch.setattr(CORL, "tell", lambda self, outcome: 1 / 0)
        with pytest.raises(ServerError, match="the learner raised ZeroDivisionError after trial 1 was stored") as info:
            c.tell(task.rollout(trial.w))
        assert info.value.status == 503
        status = c.status()
        assert status["broken"].startswith("the learner raised") and status["trials"] == 2  # told, committed
        with pytest.raises(ServerError, match="restart corl serve"):
            c.ask()
        monkeypatch.undo()
    with background(tmp_path / "s.corl", "synthetic") as url:  # restarted: the told trial is there, once
        c = Client(url, raw=True)
        assert c.status()["trials"] == 2 and c.status()["broken"] is None
        assert c.tell(task.rollout(trial.w), trial=1)["repeated"] is True


def test_a_reference_that_fails_is_the_task_s_error_and_hands_nothing_out(tmp_path, monkeypatch):
    (tmp_path / "badref.py").write_text(
        "import numpy as np\n"
        "from examples.panda_switch import PandaSwitchTask\n"
        "class Bad(PandaSwitchTask):\n"
        "    name = 'bad_reference'\n"
        "    def reference(self, w, rate=500.0):\n"
        "        t, q = super().reference(w, rate)\n"
        "        q[3, 2] = np.nan\n"
        "        return t, q\n"
        "def make():\n"
        "    return Bad()\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with background(tmp_path / "s.corl", "badref:make") as url:
        with pytest.raises(ServerError, match="the task's reference.*failed on trial 0") as info:
            Client(url).ask()
        assert info.value.status == 500
        assert Client(url).status()["pending"] is None  # nothing handed out
        assert Client(url, raw=True).ask().index == 0  # the raw parameters still can be


def test_a_store_that_cannot_commit_is_503_and_the_same_tell_succeeds_later(tmp_path, monkeypatch):
    """A full disk (here: add_outcome raising what SQLite's 'disk is full' becomes) is the store's problem,
    not the request's: 503, nothing written, and the same tell goes through once there is room."""
    task = load_task("synthetic")
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        trial = c.ask()
        outcome = task.rollout(trial.w)

        def full(self, *args, **kwargs):
            raise StoreError("could not store the outcome: database or disk is full; nothing was written")

        monkeypatch.setattr(RunStore, "add_outcome", full)
        with pytest.raises(ServerError, match="disk is full") as info:
            c.tell(outcome)
        assert info.value.status == 503 and c.status()["pending"] == 0 and c.status()["broken"] is None
        monkeypatch.undo()
        assert c.tell(outcome)["trials"] == 1


def test_a_retell_that_differs_only_in_info_says_so(tmp_path):
    task = load_task("synthetic")
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        trial = c.ask()
        outcome = task.rollout(trial.w)
        c.tell(outcome.success, outcome.return_, info={"force": 1.0})
        with pytest.raises(StateError, match=r'trial 0 was already told \(success, return .*\) with another info '
                                             r'\(\{"force": 1.0\}\); a trial is told once, its info included'):
            c.tell(outcome.success, outcome.return_, trial=0, info={"force": 2.0})
        assert c.tell(outcome.success, outcome.return_, trial=0, info={"force": 1.0})["repeated"] is True


def _bytes_and_mtime(path):
    return path.read_bytes(), path.stat().st_mtime_ns


def test_a_refused_start_leaves_the_store_byte_for_byte(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from corl.cli import app

    monkeypatch.chdir(tmp_path)
    runner = CliRunner()
    for args in (["--task", "synthetic-context", "--context", "0.1"], ["--task", "synthetic"]):
        res = runner.invoke(app, ["ask", "--store", f"{args[1]}.corl", "--raw", *args])
        assert res.exit_code == 0, res.output
    refusals = [("synthetic-context.corl", "synthetic-context", 5, "--seed 5 differs from run 1"),  # a run in a context
                ("synthetic.corl", "door", None, "is for task 'synthetic'")]
    for store, task, seed, message in refusals:
        before = _bytes_and_mtime(tmp_path / store)
        with pytest.raises(InputError, match=message):
            with background(tmp_path / store, task, seed=seed):
                pass
        assert _bytes_and_mtime(tmp_path / store) == before, store


@pytest.mark.parametrize("content, message", [
    ("t\u00e9st-token-with-an-accent", "printable ASCII characters"),
    ("x" * 5000, "holds more than 4096 bytes"),
])
def test_a_token_file_is_refused_when_no_client_could_send_it(tmp_path, content, message):
    from corl.serve import read_token

    path = tmp_path / "token.txt"
    path.write_text(content, encoding="utf-8")
    path.chmod(0o600)
    with pytest.raises(InputError, match=message):
        read_token(path)


def test_a_token_file_that_is_no_regular_file_is_refused_at_once(tmp_path):
    import os
    import threading

    from corl.serve import read_token

    fifo = tmp_path / "token.fifo"
    os.mkfifo(fifo, 0o600)
    answers = []
    reader = threading.Thread(target=lambda: answers.append(_refusal(read_token, fifo)), daemon=True)
    reader.start()
    reader.join(5)
    assert answers and "is not a regular file" in answers[0]  # not blocked waiting for a writer
    assert "is not a regular file" in _refusal(read_token, "/dev/zero")  # not read until memory runs out


def _refusal(fn, *args) -> str:
    try:
        fn(*args)
    except InputError as exc:
        return str(exc)
    return "accepted"

