"""``corl run --robots K`` and ``corl bench parallel`` (corl.fleet, corl.experiments.parallel)."""

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.store import RunStore

runner = CliRunner()


@pytest.mark.parametrize("args, message", [
    (["run", "synthetic", "--robots", "0"], "--robots must be an integer in [1, 64], got 0"),
    (["run", "synthetic", "--robots", "2", "--backend", "spark"], "--backend 'spark' is not available"),
    (["run", "synthetic", "--robots", "2", "--address", "127.0.0.1:1"], "joins a Ray or Dask cluster"),
    (["run", "synthetic", "--robots", "2", "--flip", "0.1"], "--robots with --return-noise, --flip or --context"),
    (["bench", "parallel", "synthetic", "--trial-seconds", "-1"], "--trial-seconds must be a number of seconds"),
    (["bench", "parallel", "synthetic", "--robots", "100"], "--robots must be an integer in [1, 64]"),
    (["bench", "parallel", "synthetic", "--backend", "spark"], "Dask workers (--backend dask)"),
    (["bench", "parallel", "synthetic", "--address", "127.0.0.1:1"], "add --backend ray or --backend dask"),
])
def test_bad_input_is_one_line(args, message, tmp_path):
    result = runner.invoke(app, [*args, "--out", str(tmp_path / "out")])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.output
    assert not (tmp_path / "out" / "run.corl").exists()


def test_run_with_three_robots_stores_every_trial_and_resumes(tmp_path):
    out = tmp_path / "r"
    result = runner.invoke(app, ["run", "synthetic", "--robots", "3", "--no-rollout-every-step", "--out", str(out),
                                 "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    with RunStore(out / "run.corl", readonly=True) as db:
        info = db.latest_run()
        trials = db.trials(info.id)
        assert info.config["robots"] == 3 and info.method == "CORL"  # several robots: SEIB keeps them apart
        assert [r.index for r in trials] == list(range(len(trials))) and all(r.outcome for r in trials)
        assert db.pattern(info.id).count("a") == len(trials)
        assert max(_out_at_once(db.pattern(info.id))) > 1  # trials really went out together
    assert summary["best_return"] > 0.99 and summary["trials"] == len(trials)
    again = runner.invoke(app, ["run", "synthetic", "--robots", "2", "--out", str(out), "--resume"])
    assert again.exit_code == 2 and "--robots 2 differs from the run being resumed" in again.output


def _out_at_once(pattern):
    out, seen = 0, []
    for letter in pattern:
        out += {"a": 1, "t": -1}.get(letter, 0)
        seen.append(out)
    return seen


def test_bench_parallel_writes_both_runs(tmp_path):
    out = tmp_path / "b"
    result = runner.invoke(app, ["bench", "parallel", "synthetic", "--robots", "2", "--trial-seconds", "0",
                                 "--no-rollout-every-step", "--out", str(out), "--quiet"])
    assert result.exit_code == 0, result.output
    payload = json.loads((out / "parallel.json").read_text())
    assert set(payload["runs"]) == {"1", "2"} and (out / "parallel.png").stat().st_size > 0
    for k, r in payload["runs"].items():
        assert {"wall_s", "trials", "failures", "final_return"} <= set(r) and r["final_return"] > 0.99
        assert max(int(n) for n in r["out_at_once"]) <= int(k)
    assert payload["wall_ratio"] == pytest.approx(payload["runs"]["2"]["wall_s"] / payload["runs"]["1"]["wall_s"])


@pytest.mark.slow
def test_sigkill_of_corl_run_leaves_no_worker_holding_the_store(tmp_path):
    out = tmp_path / "k"
    cmd = [sys.executable, "-m", "corl.cli", "run", "synthetic", "--robots", "4", "--out", str(out), "--quiet"]
    child = subprocess.Popen(cmd, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    deadline, told = time.monotonic() + 300, 0
    while told < 60 and time.monotonic() < deadline and child.poll() is None:
        time.sleep(0.5)
        try:
            with RunStore(out / "run.corl", readonly=True) as db:
                told = db.latest_run().n_told
        except Exception:  # noqa: BLE001 - not created yet
            pass
    assert child.poll() is None, "the run ended before it could be killed"
    child.send_signal(signal.SIGKILL)
    child.wait()
    resumed = subprocess.run([*cmd, "--resume"], env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
                             capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr  # no forked worker kept the writer lock
    with RunStore(out / "run.corl", readonly=True) as db:
        info = db.latest_run()
        trials = db.trials(info.id)
        assert info.status.value == "finished" and info.n_trials > told
        assert [r.index for r in trials] == list(range(len(trials))) and all(r.outcome for r in trials)
