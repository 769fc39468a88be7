"""Bad input to the CLI (corl/cli/, corl/arguments.py, corl/tasks/registry.py, corl/session.py):
one line ``error: ...``, exit 2, no traceback, no rollout, nothing created and the store unchanged."""

from __future__ import annotations

import contextlib
import json
import sqlite3
import sys

import pytest
from benchmark_module import load_benchmark
from cli_refusal import listing, refuse
from typer.testing import CliRunner

from corl.cli import app

runner = CliRunner()

# A user task that counts its rollouts in a file beside it, and factories that fail.
COUNTING = load_benchmark("hostile").user_task_source("counting")


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    (tmp_path / "usertask.py").write_text(COUNTING)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop("usertask", None)


def dump(path):
    with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as db:
        return list(db.iterdump())


def asked_store(folder):
    """A store whose demonstration (trial 0) is pending, as `corl ask` leaves it."""
    res = runner.invoke(app, ["ask", "--store", str(folder / "s.corl"), "--task", "synthetic", "--raw"])
    assert res.exit_code == 0, res.output
    return folder / "s.corl"


def refused(args, folder, message):
    before = listing(folder)
    res, _ = refuse(args, message)
    assert listing(folder) == before, args  # no store, .lock, output folder or file left behind
    return res


BAD_RUNS = [
    (["run", "usertask:make", "--seed", "-1"], "--seed must be an integer"),
    (["run", "usertask:make", "--method", "NOPE"], "unknown method"),
    (["run", ":"], "is not an import path"),
    (["run", "..:x"], "is not an import path"),
    (["run", "usertask:"], "is not an import path"),
    (["run", "usertask:boom"], "raised RuntimeError: the factory broke"),
    (["run", "usertask:not_a_task"], "is not a task: it lacks"),
    (["run", "nosuchmodule:make"], "cannot import"),
    (["run", "usertask:make", "--out", "afile.txt"], "is a file"),
    (["run", "usertask:make", "--out", "/proc/corl-out"], "--out /proc/corl-out cannot be created"),  # before a trial
    (["run", "usertask:make", "--store", "."], "is a folder"),
    (["bench", "synthetic", "--jobs", "0", "--starts", "1", "--out", "b"], "--jobs must be"),
    (["bench", "synthetic", "--seed", "-1", "--starts", "1", "--out", "b"], "--seed must be"),
    (["bench", "synthetic", "--starts", "1", "--out", "afile.txt"], "is a file"),
    (["bench", "synthetic", "--methods", ",", "--starts", "1", "--out", "b"], "--methods ',' names no method"),
    (["bench", "synthetic", "--methods", " , ,", "--starts", "1", "--out", "b"], "names no method"),
    # --out afile.txt too: without the cap the command would run for days, so a regression fails fast here
    (["bench", "synthetic", "--starts", "200000000", "--out", "afile.txt"], "--starts must be a number of starts in "
                                                                            "[1, 100000], got 200000000"),
    (["bench", "synthetic", "--starts", "0", "--out", "b"], "--starts must be"),
    (["bench", "door", "--jobs", "0", "--out", "d"], "--jobs must be"),
    (["bench", "door", "--force-noise", "inf", "--out", "d"], "--force-noise"),
    (["bench", "door", "--grid", "2000x2000", "--out", "d"], "makes 4000000 grid points; a sweep takes at most"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:make", "--seed", "-1"], "--seed must be"),
    (["ask", "--store", "new/s.corl", "--task", ":"], "is not an import path"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:boom"], "the factory broke"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:make", "--method", "NOPE"], "unknown method"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:make", "--rate", "nan"], "rate must be"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:make", "--rate", "inf"], "rate must be"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:make", "--rate", "1e12"], "rate must be"),
    (["ask", "--store", "new/s.corl", "--task", "usertask:make", "--rate", "0"], "rate must be"),
    (["export", "--store", "s.corl", "--out", "."], "is a folder"),
    (["export", "--store", "s.corl", "--out", "t.xlsx"], ".csv or .parquet"),
    (["export", "--store", "s.corl", "--out", "nofolder/t.csv"], "does not exist"),
    (["report", "--store", "s.corl", "--out", "afile.txt"], "is a file"),
    (["report", "--store", "s.corl", "--out", "rep", "--task", "..:x"], "is not an import path"),
    (["status", "--store", "nothing.corl"], "no store at"),
    (["tell", "--store", "s.corl", "--task", "synthetic", "--success", "no", "--return", "0.3"],
     "a failed trial is told without a return"),
    (["tell", "--store", "s.corl", "--task", ":", "--success", "yes", "--return", "0.3"], "is not an import path"),
    (["tell", "--store", "s.corl", "--task", "synthetic", "--success", "yes", "--return", "1_000"],
     "--return must be a plain finite number"),
    (["tell", "--store", "s.corl", "--task", "synthetic", "--success", "yes", "--return", "\u0661\u0662"],
     "--return must be a plain finite number"),  # Arabic-Indic digits, which float() reads as 12
]


@pytest.mark.parametrize("args, message", BAD_RUNS, ids=[" ".join(a)[:60] for a, _ in BAD_RUNS])
def test_bad_argument_is_one_line_exit_2_and_leaves_nothing(workdir, args, message):
    store = asked_store(workdir)
    (workdir / "afile.txt").write_text("not a folder")
    before = dump(store)
    refused(args, workdir, message)
    assert dump(store) == before
    assert not (workdir / "rollouts.txt").exists()  # not one rollout before the refusal


def test_a_refused_run_after_its_store_opened_leaves_no_store(workdir):
    """The task is fine but the method cannot run it (no w_bounds): refused after the checks."""
    (workdir / "nobox.py").write_text(COUNTING + "\nclass NoBox(Counting):\n    w_bounds = None\n"
                                      "def make_nobox():\n    return NoBox((0.6, 0.4))\n")
    refused(["run", "nobox:make_nobox", "--method", "CMA", "--out", "out"], workdir, "needs task.w_bounds")
    assert not (workdir / "out").exists()


def test_a_method_settings_that_raises_is_named_in_one_line(workdir):
    (workdir / "badsettings.py").write_text(COUNTING + "\nclass BadSettings(Counting):\n"
                                            "    def method_settings(self):\n        raise KeyError('gp')\n"
                                            "def make_bad():\n    return BadSettings((0.6, 0.4))\n")
    refused(["run", "badsettings:make_bad", "--out", "out"], workdir, "method_settings() raised KeyError: 'gp'")
    assert not (workdir / "rollouts.txt").exists()


def test_a_demonstration_failed_past_its_retries_is_refused_and_changes_nothing(workdir):
    store = asked_store(workdir)
    tell_no = ["tell", "--store", str(store), "--task", "synthetic", "--success", "no"]
    for trial in (0, 1):  # start_retries: two failed readings are kept and the demonstration asked again
        res = runner.invoke(app, tell_no)
        assert res.exit_code == 0 and json.loads(res.stdout)["trial"] == trial, res.output
        assert runner.invoke(app, ["ask", "--task", "synthetic", "--raw", "--store", str(store),
                                   "--out", str(workdir / "trials")]).exit_code == 0
    before = dump(store)
    refused(tell_no, workdir, "the demonstration failed 3 times")
    assert dump(store) == before
    status = json.loads(runner.invoke(app, ["status", "--store", str(store), "--json"]).stdout)
    assert status["status"] == "running" and status["pending"] == 1 and status["told"] == 2
    res = runner.invoke(app, ["tell", "--store", str(store), "--task", "synthetic", "--success", "yes",
                              "--return", "0.25"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout) == {"trial": 2, "success": True, "return": 0.25, "done": False}


def test_library_tell_refuses_a_failed_demonstration_before_storing(tmp_path):
    from corl.errors import DemonstrationFailedError
    from corl.problem import Outcome
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.synthetic import SyntheticTask

    task = SyntheticTask((0.6, 0.4))
    with RunStore(tmp_path / "a.corl") as db:
        session = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=0)
        for _ in range(2):  # start_retries: a failed reading is kept, the demonstration asked again
            session.ask()
            session.tell(Outcome(False))
        session.ask()
        with pytest.raises(DemonstrationFailedError, match="the last reading was not stored"):
            session.tell(Outcome(False))
        assert db.pending(session.run_id).index == 2 and db.latest_run().status.value == "running"
        session.tell(Outcome(True, 0.5))  # the learner is still usable
        assert session.ask().index == 3


def test_an_unexpected_error_is_one_line_from_the_entry_point(workdir, monkeypatch, capsys):
    import corl.cli as cli

    def broken():
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(cli, "app", broken)
    with pytest.raises(SystemExit) as exit_info:
        cli.main()
    assert exit_info.value.code == 1
    err = capsys.readouterr().err
    assert err.startswith("error: internal error ZeroDivisionError: a bug") and len(err.splitlines()) == 1


def test_plain_number_takes_decimal_notation_only():
    from corl.arguments import plain_number
    from corl.errors import InputError

    for text, value in (("0.25", 0.25), ("-1.5e3", -1500.0), ("+3", 3.0), (".5", 0.5), ("5.", 5.0), (" 2 ", 2.0)):
        assert plain_number("--return", text) == pytest.approx(value, rel=1e-15)
    for text in ("1_000", "nan", "-inf", "infinity", "0x10", "1e999", "", "1e", ".", "--1", "\u0661"):
        with pytest.raises(InputError, match="--return must be"):
            plain_number("--return", text)


def test_starts_are_capped_at_a_documented_maximum():
    from corl.arguments import MAX_STARTS, check
    from corl.errors import InputError

    check(starts=("--starts", MAX_STARTS))
    with pytest.raises(InputError, match=f"in \\[1, {MAX_STARTS}\\]"):
        check(starts=("--starts", MAX_STARTS + 1))
    res = runner.invoke(app, ["bench", "synthetic", "--help"], env={"COLUMNS": "300"})
    assert f"at most {MAX_STARTS}" in res.output
