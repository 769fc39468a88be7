"""The store as a file: one writer per file under any name, read-only media, one file at rest, and
damaged fields that give a one-line error (corl/store/lock.py, sqlite.py, records.py)."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.problem import Outcome, Proposal
from corl.session import StoredRun
from corl.store import RunStore, StoreError
from corl.tasks.registry import load_task
from test_store import HOLD_WRITER  # a child that holds a store open as its writer

runner = CliRunner()

WRITE_FOREVER = textwrap.dedent(
    """
    import sys
    import numpy as np
    from corl.problem import Outcome, Proposal
    from corl.store import RunStore
    store = RunStore(sys.argv[1])
    run = store.create_run(task="door", method="corl", seed=0, config={}, versions={})
    k = 0
    while True:
        rng = np.random.default_rng(k)
        store.add_proposal(run, Proposal(k, rng.normal(size=1200), rng.normal(size=2), "reinforcement", k // 10))
        store.add_outcome(run, k, Outcome(bool(k % 3), float(k) if k % 3 else None, {"k": k}))
        k += 1
        if k == 40:
            print("ready", flush=True)
    """
)


@contextlib.contextmanager
def holding_writer(path):
    child = subprocess.Popen([sys.executable, "-c", HOLD_WRITER, str(path)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        yield child
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()


def filled(path, trials=3):
    with RunStore(path) as store:
        run = store.create_run(task="synthetic", method="corl", seed=0, config={"a": 1}, versions={})
        for k in range(trials):
            store.add_proposal(run, Proposal(k, np.arange(3.0) + k, np.array([0.1 * k]), "optimization"))
            store.add_outcome(run, k, Outcome(True, float(k)))
    return path


def rows(path):
    with RunStore(path, readonly=True) as store:
        return [(r.index, r.proposal.w.tobytes(), r.outcome.return_ if r.outcome else None)
                for r in store.trials(store.latest_run().id)]


def dump(path):
    """The store's content as SQL text: equal dumps mean nothing stored changed."""
    with contextlib.closing(sqlite3.connect(f"file:{path}?mode=ro", uri=True)) as db:
        return list(db.iterdump())


def sidecars(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(("-wal", "-shm", "-journal", ".lock")))


# -- one writer per file, whatever its name -------------------------------------------------------
def test_symlink_and_hardlink_get_no_second_writer(tmp_path):
    store = tmp_path / "a.corl"
    symlink = tmp_path / "s.corl"
    os.symlink(store, symlink)
    with holding_writer(store) as child:
        with pytest.raises(StoreError, match=f"already open for writing by process {child.pid} .*links included"):
            RunStore(symlink)
        os.link(store, tmp_path / "h.corl")
        with pytest.raises(StoreError, match=f"already open for writing by process {child.pid} "):
            RunStore(tmp_path / "h.corl")
    with RunStore(store, readonly=True) as reader:
        assert reader.pending(1).index == 0  # the refused writers changed nothing
    # no writer may write a file with two names (SQLite keeps a write-ahead log per name)
    for name in ("a.corl", "h.corl"):
        with pytest.raises(StoreError, match="has 2 names \\(hard links\\)"):
            RunStore(tmp_path / name)
    os.unlink(tmp_path / "h.corl")
    with RunStore(symlink) as writer:  # one name again: the symlink writes the same file
        with pytest.raises(StoreError, match="that is this very process"):
            RunStore(store)
        writer.add_outcome(1, 0, Outcome(False))
    assert rows(store) == [(0, np.arange(4.0).tobytes(), None)]
    assert sidecars(tmp_path) == []  # no .lock, no log left beside the store


def test_refused_writer_creates_nothing(tmp_path):
    with pytest.raises(StoreError, match="no store at"):
        RunStore(tmp_path / "absent.corl", create=False)
    bad = tmp_path / "other.sqlite"
    with sqlite3.connect(bad) as db:
        db.execute("CREATE TABLE x (y)")
    with pytest.raises(StoreError, match="another program"):
        RunStore(bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.sqlite"]


# -- one file at rest -----------------------------------------------------------------------------
def test_a_closed_store_is_one_file(tmp_path):
    store = filled(tmp_path / "run.corl")
    assert sidecars(tmp_path) == []
    copy = tmp_path / "copy"
    copy.mkdir()
    shutil.copy(store, copy / "run.corl")
    assert rows(copy / "run.corl") == rows(store)


def test_any_command_folds_the_log_a_killed_run_left(tmp_path):
    store = tmp_path / "run.corl"
    child = subprocess.Popen([sys.executable, "-c", WRITE_FOREVER, str(store)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "ready"
        time.sleep(0.05)
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait()
    wal = tmp_path / "run.corl-wal"
    assert wal.stat().st_size > 100_000  # the killed writer's trials sit in its log
    res = runner.invoke(app, ["status", "--store", str(store)])
    assert res.exit_code == 0, res.output
    assert not wal.exists() or wal.stat().st_size == 0
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(store, alone / "run.corl")  # the store file alone, without any -wal
    got = rows(alone / "run.corl")
    assert len(got) >= 40 and got == rows(store)
    assert f"trials {len(got)}" in res.output


# -- read-only media ------------------------------------------------------------------------------
@contextlib.contextmanager
def immutable(*paths):
    """Make paths immutable (``chattr +i``), which even root cannot write or create files in."""
    done = []
    try:
        for p in paths:
            if subprocess.run(["chattr", "+i", str(p)], capture_output=True).returncode != 0:
                pytest.skip("chattr +i is not available here (filesystem or capabilities)")
            done.append(p)
        yield
    finally:
        for p in done:
            subprocess.run(["chattr", "-i", str(p)], check=True)


@pytest.mark.parametrize("at_rest", ["rollback", "wal"])
def test_read_only_media_are_read(tmp_path, at_rest):
    folder = tmp_path / "media"
    folder.mkdir()
    store = filled(folder / "run.corl", trials=4)
    if at_rest == "wal":  # as an older corl left it: a WAL-mode header, no log file
        with sqlite3.connect(store) as db:
            db.execute("PRAGMA journal_mode = WAL")
        assert sidecars(folder) == []
    expected = rows(store)
    out = tmp_path / "out"
    out.mkdir()
    with immutable(store, folder):
        with pytest.raises(OSError):
            (folder / "probe").write_text("x")  # really read-only, even for root
        for args in (["status", "--store", str(store)], ["runs", "--store", str(store)],
                     ["export", "--store", str(store), "--out", str(out / "t.csv")],
                     ["report", "--store", str(store), "--out", str(out / "rep"), "--no-video", "--quiet"]):
            res = runner.invoke(app, args)
            assert res.exit_code == 0, (args, res.output)
        assert rows(store) == expected
        res = runner.invoke(app, ["ask", "--store", str(store), "--task", "synthetic", "--raw"])
        assert res.exit_code == 2 and "is not a writable folder" in res.output  # refused before any open
    assert (out / "t.csv").read_text().count("\n") == 5
    assert (out / "rep" / "run_1.html").is_file()
    assert sidecars(folder) == []


# -- damaged fields -------------------------------------------------------------------------------
@pytest.mark.parametrize("sql", [
    "UPDATE runs SET config = '{not json'",
    "UPDATE runs SET versions = '[1, 2]'",
    "UPDATE runs SET seed = 'abc'",
    "UPDATE outcomes SET info = 'nope' WHERE trial_index = 1",
    "UPDATE trials SET w_shape = '[2' WHERE trial_index = 2",
    "UPDATE trials SET theta_shape = '[-1]' WHERE trial_index = 0",
])
def test_damaged_fields_give_one_line(tmp_path, sql):
    store = tmp_path / "run.corl"
    task = load_task("synthetic", seed=0)
    with RunStore(store) as db:
        StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=0).run(task, max_trials=3)
    with sqlite3.connect(store) as db:
        db.execute(sql)
    before = dump(store)
    for args in (["status", "--store", str(store)], ["runs", "--store", str(store)],
                 ["export", "--store", str(store), "--out", str(tmp_path / "t.csv")],
                 ["report", "--store", str(store), "--out", str(tmp_path / "rep"), "--quiet"],
                 ["ask", "--store", str(store), "--task", "synthetic", "--raw"]):
        res = runner.invoke(app, args)
        if res.exit_code == 0:  # `runs` reads no trials: a damaged trial does not concern it
            assert args[0] == "runs" and "trial" in sql, res.output
            continue
        assert res.exit_code == 2 and isinstance(res.exception, SystemExit), (args, res.output)
        lines = res.output.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:") and "damaged" in lines[0], (args, res.output)
    assert dump(store) == before


def test_unwritable_place_reads_without_creating_files(tmp_path, monkeypatch):
    """Where chattr is unavailable: the same path taken when os.access says the place is not writable."""
    import corl.store.sqlite as sqlite_module

    store = filled(tmp_path / "run.corl", trials=2)
    with sqlite3.connect(store) as db:
        db.execute("PRAGMA journal_mode = WAL")  # the header an older corl left: WAL mode, no log file
    expected = rows(store)
    real_access = os.access
    monkeypatch.setattr(sqlite_module.os, "access", lambda p, mode: not mode & os.W_OK and real_access(p, mode))
    assert rows(store) == expected
    assert sidecars(tmp_path) == []  # neither -shm nor -wal was created
    (tmp_path / "run.corl-wal").write_bytes(b"\0" * 64)  # a log with data in a read-only place: say so
    with pytest.raises(StoreError, match="read-only place with trials still in its write-ahead log"):
        RunStore(store, readonly=True)
