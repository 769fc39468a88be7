"""`corl ask`, `corl tell` and `corl run --resume` refused (corl/cli/learn.py, corl/session.py): one line
``error: ...``, exit 2, and every store byte for byte as it was, its modification time included.

A refused command never opens a store for writing: it checks its flags, loads the task and replays
the run from a read-only open first, so SQLite never rewrites the file's header (the change counter
at bytes 24-27 and 92-95) nor touches its mtime.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest
from cli_refusal import copy_of, refuse, state
from typer.testing import CliRunner

from corl.cli import app

runner = CliRunner()

# Task factories that misbehave: a user module beside the stores.
USERTASK = """
import sys
from corl.tasks.synthetic import SyntheticTask

class Other(SyntheticTask):
    name = "other"

class Leaving(SyntheticTask):
    def rollout(self, w):
        sys.exit(0)

def other():
    return Other((0.6, 0.4))

def boom():
    raise RuntimeError("the factory broke")

def exits():
    sys.exit(0)

def exits_3():
    raise SystemExit(3)

def leaving(seed=0):
    return Leaving(Leaving.random_start(__import__("numpy").random.default_rng([seed, 2016])))
"""


def corl(folder: Path, *args: str) -> str:
    res = runner.invoke(app, list(args))
    assert res.exit_code == 0, (args, res.output)
    return res.stdout


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """``s.corl``: trial 0 told, trial 1 pending; ``demo.corl``: the demonstration read twice as failed and
    asked again (start_retries); ``told.corl``: nothing pending; ``fin.corl``: a finished run; all CORL+PIBU
    on the synthetic task, seed 0."""
    folder = tmp_path_factory.mktemp("stores")
    s, demo, told, fin = (str(folder / n) for n in ("s.corl", "demo.corl", "told.corl", "fin.corl"))
    ask = ["ask", "--task", "synthetic", "--raw", "--out", str(folder / "trials"), "--store"]
    corl(folder, *ask, demo)
    shutil.copy(demo, told)
    corl(folder, "tell", "--store", told, "--task", "synthetic", "--success", "yes", "--return", "0.2")
    shutil.copy(told, s)
    corl(folder, *ask, s)
    for _ in range(2):  # start_retries: two failed readings are kept, the demonstration asked again each time
        corl(folder, "tell", "--store", demo, "--task", "synthetic", "--success", "no")
        corl(folder, *ask, demo)
    corl(folder, "run", "synthetic", "--store", fin, "--out", str(folder / "finout"), "--no-video", "-q")
    shutil.rmtree(folder / "trials")
    shutil.rmtree(folder / "finout")
    (folder / "usertask.py").write_text(USERTASK)
    return folder


@pytest.fixture
def workdir(template, tmp_path, monkeypatch):
    yield copy_of(template, tmp_path, monkeypatch)
    sys.modules.pop("usertask", None)


def refused(args: list[str], folder: Path, message: str) -> str:
    before = state(folder)
    _, line = refuse(args, message)
    after = state(folder)
    assert after.keys() == before.keys(), (args, sorted(after.keys() ^ before.keys()))  # nothing new, nothing gone
    for name, (data, mtime) in before.items():
        assert after[name][0] == data, (args, name, "bytes changed")  # e.g. the header's change counter
        assert after[name][1] == mtime, (args, name, "mtime changed")
    return line


TELL = ["tell", "--task", "synthetic", "--store"]
ASK = ["ask", "--task", "synthetic", "--raw", "--store"]
RESUME = ["run", "synthetic", "--resume", "--out", "o", "--no-video", "-q", "--store"]

REFUSED = [
    ([*TELL, "s.corl", "--success", "maybe"], "--success must be yes or no"),
    ([*TELL, "s.corl", "--success", "yes", "--return", "1_000"], "plain finite number"),
    ([*TELL, "s.corl", "--success", "yes", "--return", "nan"], "plain finite number"),
    ([*TELL, "s.corl", "--success", "yes"], "needs a finite return"),
    ([*TELL, "s.corl", "--success", "no", "--return", "0.3"], "a failed trial is told without a return"),
    ([*TELL, "told.corl", "--success", "yes", "--return", "0.3"], "no pending trial"),
    ([*TELL, "fin.corl", "--success", "yes", "--return", "0.3"], "no pending trial"),
    ([*TELL, "demo.corl", "--success", "no"], "the demonstration failed"),
    (["tell", "--task", "usertask:other", "--store", "s.corl", "--success", "yes", "--return", "0.3"],
     "is for task 'synthetic'"),
    (["tell", "--task", "usertask:boom", "--store", "s.corl", "--success", "yes", "--return", "0.3"],
     "the factory broke"),
    (["tell", "--task", "usertask:exits", "--store", "s.corl", "--success", "yes", "--return", "0.3"],
     "called sys.exit(0) in exits"),
    ([*ASK, "s.corl", "--method", "CORL+UCB", "--seed", "7"], "--method CORL+UCB differs from the run"),
    ([*ASK, "s.corl", "--seed", "7"], "--seed 7 differs from the run"),
    ([*ASK, "told.corl", "--method", "CMA"], "--method CMA differs from the run"),
    ([*ASK, "fin.corl"], "has finished"),
    (["ask", "--task", "synthetic", "--store", "s.corl"], "has no reference(w, rate)"),
    (["ask", "--task", "usertask:other", "--raw", "--store", "s.corl"], "is for task 'synthetic'"),
    (["ask", "--task", "usertask:boom", "--raw", "--store", "s.corl"], "the factory broke"),
    (["ask", "--task", "usertask:exits_3", "--raw", "--store", "s.corl"], "called sys.exit(3)"),
    ([*RESUME, "s.corl", "--seed", "9"], "--seed 9 differs from the run being resumed"),
    ([*RESUME, "s.corl", "--method", "CORL+CMA"], "--method CORL+CMA differs from the run being resumed"),
    ([*RESUME, "s.corl", "--no-rollout-every-step"], "differs from the run being resumed"),
    (["run", "usertask:other", "--resume", "--out", "o", "-q", "--store", "s.corl"], "is for task 'synthetic'"),
    (["run", "usertask:exits", "--resume", "--out", "o", "-q", "--store", "s.corl"], "called sys.exit(0)"),
]


@pytest.mark.parametrize("args, message", REFUSED, ids=[" ".join(a)[:70] for a, _ in REFUSED])
def test_a_refused_command_leaves_every_store_byte_identical_with_its_mtime(workdir, args, message):
    refused(args, workdir, message)


def test_ask_on_a_finished_run_says_so_and_what_to_do(workdir):
    line = refused([*ASK, "fin.corl"], workdir, "run 1 in fin.corl has finished")
    assert "corl report --store fin.corl" in line


def test_ask_accepts_the_flags_of_the_stored_run(workdir):
    out = json.loads(corl(workdir, *ASK, "s.corl", "--method", "CORL+PIBU", "--seed", "0"))
    assert out["trial"] == 1  # the pending trial, handed out again


def test_an_accepted_tell_writes_and_a_retold_trial_is_then_refused(workdir):
    out = json.loads(corl(workdir, *TELL, "s.corl", "--success", "yes", "--return", "-1.5e-1"))
    assert out["trial"] == 1 and out["return"] == pytest.approx(-0.15, abs=1e-15)
    refused([*TELL, "s.corl", "--success", "yes", "--return", "0.1"], workdir, "no pending trial")


def test_sys_exit_in_a_rollout_of_corl_run_is_an_error_and_keeps_the_trials(workdir):
    res = runner.invoke(app, ["run", "usertask:leaving", "--out", "o2", "--store", "new.corl", "-q", "--no-video"])
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit), res.output
    line = res.stderr.strip()
    assert line.startswith("error: the task's code called sys.exit(0) in rollout (usertask.py:") and "\n" not in line
    status = json.loads(corl(workdir, "status", "--store", "new.corl", "--json"))
    assert status["trials"] == 1 and status["pending"] == 1  # the demonstration was handed out and kept


def test_a_store_changed_between_the_read_and_the_write_is_refused(workdir, monkeypatch):
    """Another process tells the pending trial while this `tell` replays: nothing is told twice."""
    import corl.cli.learn as learn

    real = learn._run_to_tell

    def meanwhile(task, store, outcome):
        session = real(task, store, outcome)
        from corl.problem import Outcome
        from corl.store import RunStore

        with RunStore(store) as db:  # the other process
            db.add_outcome(session.run_id, 1, Outcome(True, 0.5))
        return session

    monkeypatch.setattr(learn, "_run_to_tell", meanwhile)
    res = runner.invoke(app, [*TELL, "s.corl", "--success", "yes", "--return", "0.3"])
    assert res.exit_code == 2 and "changed while this command read it" in res.stderr, res.output
    status = json.loads(corl(workdir, "status", "--store", "s.corl", "--json"))
    assert status["told"] == 2 and status["best_observed"]["return"] == pytest.approx(0.5, abs=1e-15)
