import contextlib
import json
import os
import random
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError, StateError
from corl.problem import Outcome
from corl.session import StoredRun
from corl.store import RunStore, StoreError
from corl.settings import PAPER_SYNTHETIC
from corl.tasks.synthetic import SyntheticTask

CORL = [sys.executable, "-m", "corl.cli"]
FIGURES = 1 << 30  # progress(): corl run writes its figures, after every trial


def dump(path):
    """The store's content as SQL text: equal dumps mean nothing stored changed."""
    with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as db:
        return list(db.iterdump())


def trials_of(path):
    from corl.store.records import EmptyStoreError

    try:
        db = RunStore(path, readonly=True)
    except EmptyStoreError:  # killed after creating the file, before the store's first commit
        return [], None
    with db:
        run = db.latest_run()
        if run is None:  # killed after creating the store, before the run's first commit
            return [], None
        return [(t.index, t.proposal.step, t.proposal.w.tobytes(), t.proposal.theta.tobytes(),
                 None if t.outcome is None else (t.outcome.success, t.outcome.return_))
                for t in db.trials(run.id)], run.status.value


def test_stored_run_resumes_exactly(tmp_path):
    task = SyntheticTask((0.2, 1.1))
    with RunStore(tmp_path / "a.corl") as db:
        ref = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=3)
        ref.run(task)
        expected = [(p.index, p.w.tobytes(), o.success) for p, o in ref.history]
    with RunStore(tmp_path / "b.corl") as db:
        first = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=3)
        first.run(task, max_trials=57)
        first.ask()  # handed out, never answered
    with RunStore(tmp_path / "b.corl") as db:
        again = StoredRun.open(db, task)
        assert again.learner.ask().index == 57  # the pending trial is offered again
        again.run(task)
        got = [(p.index, p.w.tobytes(), o.success) for p, o in again.history]
    assert got == expected


def test_wrong_task_and_tell_without_pending(tmp_path):
    task = SyntheticTask((0.2, 1.1))
    with RunStore(tmp_path / "a.corl") as db:
        s = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=0)
        with pytest.raises(StateError):
            s.tell(Outcome(True, 1.0))

        class Other(SyntheticTask):
            name = "other"

        with pytest.raises(InputError, match="task"):
            StoredRun.open(db, Other((0.2, 1.1)))


def test_second_writer_is_refused_and_store_unchanged(tmp_path):
    path = tmp_path / "s.corl"
    runner = CliRunner()
    assert runner.invoke(app, ["ask", "--store", str(path), "--task", "synthetic", "--raw"]).exit_code == 0
    before = dump(path)
    holder = subprocess.Popen([sys.executable, "-c",
                               "import sys, time; from corl.store import RunStore; s = RunStore(sys.argv[1]); "
                               "print('open', flush=True); time.sleep(30)", str(path)], stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline().strip() == b"open"
        res = runner.invoke(app, ["tell", "--store", str(path), "--task", "synthetic", "--success", "yes",
                                  "--return", "0.5"])
        assert res.exit_code == 2 and "error" in res.output.lower()
    finally:
        holder.kill()
        holder.wait()
    assert trials_of(path)[0][0][4] is None  # the pending trial is still pending
    assert dump(path) == before


def test_cli_ask_tell_errors_leave_store_as_it_was(tmp_path):
    path = tmp_path / "s.corl"
    runner = CliRunner()
    res = runner.invoke(app, ["ask", "--store", str(path), "--task", "synthetic", "--seed", "1", "--raw"])
    assert res.exit_code == 0, res.output
    asked = json.loads(res.output.strip().splitlines()[-1])
    assert Path(asked["csv"]).exists() and Path(asked["npz"]).exists()
    state = trials_of(path)
    for args in (["--success", "maybe"], ["--success", "yes", "--return", "nan"],
                 ["--success", "yes", "--return", "inf"], ["--success", "yes", "--return", "lots"],
                 ["--success", "yes"]):
        res = runner.invoke(app, ["tell", "--store", str(path), "--task", "synthetic", *args])
        assert res.exit_code == 2, (args, res.output)
        assert len(res.output.strip().splitlines()) == 1
        assert trials_of(path) == state
    ok = runner.invoke(app, ["tell", "--store", str(path), "--task", "synthetic", "--success", "yes", "--return", "0.2"])
    assert ok.exit_code == 0, ok.output
    twice = runner.invoke(app, ["tell", "--store", str(path), "--task", "synthetic", "--success", "yes", "--return", "0.2"])
    assert twice.exit_code == 2 and "no pending trial" in twice.output
    bad = tmp_path / "bad.corl"
    bad.write_bytes(os.urandom(4096))
    raw = bad.read_bytes()
    res = runner.invoke(app, ["status", "--store", str(bad)])
    assert res.exit_code == 2 and "damaged" in res.output and bad.read_bytes() == raw
    res = runner.invoke(app, ["ask", "--store", str(path), "--task", "no.such.module:make_task"])
    assert res.exit_code == 2 and "cannot import" in res.output
    res = runner.invoke(app, ["export", "--store", str(path), "--out", str(tmp_path / "t.csv")])
    assert res.exit_code == 0 and (tmp_path / "t.csv").read_text().count("\n") == 2


def progress(proc):
    """What ``corl run`` (without --quiet) tells on stderr as it goes: the index of each trial as it is told,
    then FIGURES once it writes its figures and summary."""
    for line in proc.stderr:
        if line.startswith("trial "):
            yield int(line.split()[1])
        elif line.startswith("writing figures"):
            yield FIGURES


@pytest.mark.slow
def test_sigkill_at_random_moments_then_resume_equals_uninterrupted(tmp_path):
    """``corl run`` SIGKILLed at 8 random moments spread over its phases, resumed after each: one just after
    the store's creation and first trial, five in the trials (one in each fifth), two while it writes its
    figures and summary. Every stored state is a prefix of the uninterrupted run's, and the last resume
    ends equal to it."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    args = ["run", "synthetic", "--seed", "1"]
    ref = tmp_path / "ref"
    proc = subprocess.Popen(CORL + args + ["--out", str(ref)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    t0 = None
    for step in progress(proc):
        if step == FIGURES:
            t0 = time.monotonic()
    assert proc.wait() == 0 and t0 is not None, "corl run did not say 'writing figures'"
    writing = time.monotonic() - t0  # the figures and summary
    expected, status = trials_of(ref / "run.corl")
    assert status == "finished" and len(expected) > 100
    rng = random.Random(7)
    fifths = [int((i + rng.uniform(0.1, 0.9)) / 5 * len(expected)) for i in range(5)]
    plan = [(0, rng.uniform(0, 0.01)), *((n, rng.uniform(0, 0.02)) for n in fifths),
            (FIGURES, rng.uniform(0.0, 0.1) * writing), (FIGURES, rng.uniform(0.3, 0.8) * writing)]
    out = tmp_path / "killed"
    kills = 0
    for target, delay in plan:  # kill once it has told trial ``target`` (or begun its figures), ``delay`` s later
        cmd = CORL + args + ["--out", str(out)] + (["--resume"] if (out / "run.corl").exists() else [])
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        if any(step >= target for step in progress(proc)):
            time.sleep(delay)
        else:  # it ended before the kill: it must be the reference
            proc.wait()
        if proc.poll() is not None:
            assert proc.returncode == 0
            assert trials_of(out / "run.corl") == (expected, "finished")
            shutil.rmtree(out)  # the next kills on a fresh store
            continue
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        kills += 1
        if (out / "run.corl").exists():
            partial, _ = trials_of(out / "run.corl")
            assert partial == expected[: len(partial)] or (
                partial[:-1] == expected[: len(partial) - 1] and partial[-1][4] is None)
    resume = ["--resume"] if (out / "run.corl").exists() else []
    res = subprocess.run(CORL + args + ["--out", str(out), "--quiet"] + resume, env=env, capture_output=True)
    assert res.returncode == 0, res.stderr.decode()
    got, status = trials_of(out / "run.corl")
    assert status == "finished"
    assert got == expected
    assert kills >= len(plan) - 1  # the last may come after a resumed run's quicker figures
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trials"] == len(expected)


def test_export_parquet_round_trip(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    task = SyntheticTask((0.2, 1.1))
    with RunStore(tmp_path / "a.corl") as db:
        s = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=0)
        s.run(task, max_trials=30)
        table_path, arrays_path = db.export(s.run_id, tmp_path / "t.parquet")
        expected = [(p.index, o.success, o.return_) for p, o in s.history]
    table = pq.read_table(table_path).to_pydict()
    got = list(zip(table["index"], [bool(v) for v in table["success"]], table["return"]))
    assert got == expected
    w = np.load(arrays_path, allow_pickle=False)["w"]
    assert w.shape == (30, 2)


def test_corl_overrides_keep_the_default_settings_of_a_user_task(monkeypatch):
    # --no-rollout-every-step used to rebuild a user's task with the synthetic paper GPs, not the
    # fitted ones a user's task gets otherwise
    import corl.methods as methods
    from corl.session import _build

    seen = {}
    monkeypatch.setattr(methods, "make_method", lambda name, task, *, seed, settings=None: seen.update(s=settings))

    class Mine(SyntheticTask):
        name = "mine"
        method_settings = None  # a user's task: no preset of its own

    _build(Mine(), "CORL", 0, {"rollout_every_step": False})
    assert seen["s"].regression == methods.USER_SETTINGS.regression
    assert seen["s"].regression.fit_hyperparameters and seen["s"].corl.rollout_every_step is False
    _build(SyntheticTask(), "CORL+PIBU", 0, {"rollout_every_step": False})
    assert seen["s"].regression == PAPER_SYNTHETIC.regression  # the paper's, for the paper's task
    assert not seen["s"].regression.fit_hyperparameters


@pytest.mark.parametrize("left", ["empty file", "header only"])
def test_resume_starts_over_from_a_store_whose_creation_was_killed(tmp_path, left):
    """A kill between creating the file and the store's first commit leaves an empty (or, once
    the log mode is set, a header-only) SQLite file: --resume starts the run, nothing was lost."""
    import sqlite3

    out = tmp_path / "killed"
    out.mkdir()
    store = out / "run.corl"
    store.touch()
    if left == "header only":
        con = sqlite3.connect(store)
        con.execute("PRAGMA journal_mode=WAL")
        con.close()
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    args = ["run", "synthetic", "--seed", "1", "--quiet", "--out", str(out), "--resume"]
    res = subprocess.run(CORL + args, env=env, capture_output=True)
    assert res.returncode == 0, res.stderr.decode()
    got, status = trials_of(store)
    assert status == "finished" and len(got) > 100
    empty = tmp_path / "empty.corl"
    empty.touch()
    listed = subprocess.run(CORL + ["runs", "--store", str(empty)], env=env, capture_output=True)
    assert listed.returncode == 2 and b"is empty, not a corl store" in listed.stderr  # reading: a clear error
