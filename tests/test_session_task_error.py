"""A task whose code raises inside the learner (corl/session.py, corl/store/resume.py, corl/cli/learn.py):
the live run, every resume and a restarted server name the task's member and the trial in one line (exit 2),
and the run goes on once the task is fixed, or ends there with ``corl run --resume --end-at-error``, every
told trial kept."""

from __future__ import annotations

import json
import sys

import pytest
from cli_refusal import refuse, state
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import StateError, TaskError
from corl.store import RunStore

runner = CliRunner()

# cost_residuals has no model beyond theta = LIMIT (read at each call, so a test can "fix" the task)
BADTASK = """
import os
import numpy as np
from corl.tasks.synthetic import SyntheticTask

class Bad(SyntheticTask):
    name = "bad"

    def cost_residuals(self, w):
        if np.arctan2(w[1], w[0]) > float(os.environ.get("BAD_LIMIT", "0.9")):
            raise ValueError("no model beyond the limit")
        return super().cost_residuals(w)

def make_task(seed=0):
    return Bad(w0=(0.6, 0.5))
"""
RUN = ["run", "badtask:make_task", "--store", "s.corl", "--out", "o", "--no-video", "-q"]


@pytest.fixture
def folder(tmp_path, monkeypatch):
    (tmp_path / "badtask.py").write_text(BADTASK)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("BAD_LIMIT", raising=False)
    yield tmp_path
    sys.modules.pop("badtask", None)


def stored(path):
    with RunStore(path, readonly=True) as db:
        run = db.latest_run()
        return [(t.index, t.proposal.w.tobytes(), t.outcome.success, t.outcome.return_)
                for t in db.trials(run.id)], run.status.value


def broken_run():
    """The live run: the task raises on the follow-up of its last told trial; returns (error line, told)."""
    _, line = refuse(RUN, "the task's cost_residuals raised ValueError: no model beyond the limit, as the "
                          "learner took in trial ")
    trials, status = stored("s.corl")
    assert status == "running" and len(trials) > 10  # every told trial kept, the run left open
    assert f"as the learner took in trial {len(trials) - 1};" in line
    assert "corl run badtask:make_task --store s.corl --resume --end-at-error" in line
    return line, trials


def test_a_task_error_is_named_at_every_resume_and_the_run_can_be_ended_there(folder):
    _, trials = broken_run()
    last = len(trials) - 1
    before = state(folder)
    for args in (RUN + ["--resume"], ["ask", "--task", "badtask:make_task", "--raw", "--store", "s.corl"]):
        _, line = refuse(args, f"cannot resume run 1: the task's cost_residuals raised ValueError: no model beyond "
                               f"the limit, as the learner took in trial {last}; the store keeps all {last + 1} told")
        assert "--end-at-error" in line
    assert state(folder) == before  # refused: the store's bytes and mtime as they were
    refuse(RUN + ["--end-at-error"], "--end-at-error ends the run being resumed; add --resume")

    res = runner.invoke(app, RUN + ["--resume", "--end-at-error"])
    assert res.exit_code == 0, res.output
    assert stored("s.corl") == (trials, "finished")  # every trial as it was, the run ended
    summary = json.loads((folder / "o" / "summary.json").read_text())
    assert summary["ended"] == {"trial": last, "member": "cost_residuals",
                                "error": "ValueError: no model beyond the limit"}
    assert summary["trials"] == last + 1 and summary["stop_reason"] == "error"
    res = runner.invoke(app, RUN + ["--resume"])  # the ended run replays up to its error, and runs no trial
    assert res.exit_code == 0, res.output
    assert stored("s.corl") == (trials, "finished")
    res = runner.invoke(app, ["status", "--store", "s.corl", "--json"])
    assert json.loads(res.stdout)["ended"]["trial"] == last
    refuse(["ask", "--task", "badtask:make_task", "--raw", "--store", "s.corl"], "has finished")


def test_a_fixed_task_resumes_and_a_changed_one_is_told_apart(folder, monkeypatch):
    _, trials = broken_run()
    monkeypatch.setenv("BAD_LIMIT", "0.75")  # raises earlier than when the run ran: the task changed
    _, line = refuse(RUN + ["--resume", "--end-at-error"], "cannot resume run 1: the task's cost_residuals raised")
    assert "When the run went on past trial" in line and "its code has changed since" in line
    monkeypatch.setenv("BAD_LIMIT", "10")  # fixed: the same values where it ran, a value where it raised
    refuse(RUN + ["--resume", "--end-at-error"], "resumes without an error of the task's code")
    res = runner.invoke(app, RUN + ["--resume"])
    assert res.exit_code == 0, res.output
    resumed, status = stored("s.corl")
    assert status == "finished" and resumed[:len(trials)] == trials and len(resumed) > len(trials)


def test_a_restarted_server_names_the_task_error_and_serves_the_ended_run(folder):
    pytest.importorskip("uvicorn")
    from corl.client import Client, ServerError
    from corl.serve import background
    from corl.tasks.registry import load_task

    task = load_task("badtask:make_task")
    with background(folder / "s.corl", "badtask:make_task") as url:
        c = Client(url, raw=True)
        with pytest.raises(ServerError, match="the task's cost_residuals raised ValueError") as info:
            while True:
                c.tell(task.rollout(c.ask().w))
        assert info.value.status == 503 and "--end-at-error" in str(info.value)
        assert "restart corl serve on the same store" not in str(info.value)  # a restart meets it again
    trials, _ = stored(folder / "s.corl")
    with pytest.raises(TaskError, match=f"cannot resume run 1: the task's cost_residuals .* trial {len(trials) - 1}"):
        with background(folder / "s.corl", "badtask:make_task"):
            pass
    assert runner.invoke(app, RUN + ["--resume", "--end-at-error"]).exit_code == 0
    with background(folder / "s.corl", "badtask:make_task") as url:
        c = Client(url, raw=True)
        assert c.status()["done"] and c.status()["trials"] == len(trials)
        with pytest.raises(StateError, match="where the task's cost_residuals raised"):  # 409
            c.ask()
