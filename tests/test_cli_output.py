"""What the long commands print: progress on stderr, the result on stdout, ``--quiet`` and ``--json``."""

from __future__ import annotations

import io
import json

import pytest
from rich.console import Console
from typer.testing import CliRunner

from corl.cli import app
from corl.progress import Mode, Tracker, choose_mode

BENCH = ["bench", "synthetic", "--starts", "2", "--seed", "0", "--methods", "CORL+PIBU", "--jobs", "1"]


def _invoke(args):
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    return res


def test_bench_synthetic_default_json_and_quiet(tmp_path):
    res = _invoke(BENCH + ["--out", str(tmp_path)])  # stderr is no terminal here: one log line per start
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 2 and lines[-1].startswith("bench synthetic | CORL+PIBU 2/2 | failures ")
    assert "best R +1.0000" in lines[-1]
    assert "CORL+PIBU" in res.stdout and "paper" in res.stdout

    res = _invoke(BENCH + ["--out", str(tmp_path), "--json"])
    doc = json.loads(res.stdout)  # the whole of stdout is one document
    assert set(doc) >= {"methods", "found_tolerance", "seed", "starts", "wall_seconds", "versions", "file"}
    assert doc["methods"]["CORL+PIBU"]["starts"] == 2
    assert json.loads((tmp_path / "synthetic.json").read_text())["methods"] == doc["methods"]
    assert "best R" in res.stderr

    res = _invoke(BENCH + ["--out", str(tmp_path), "--quiet", "--json"])
    assert res.stderr == ""
    assert json.loads(res.stdout)["starts"] == 2


def test_run_default_quiet_json_and_store_listings(tmp_path):
    out = tmp_path / "run"
    res = _invoke(["run", "synthetic", "--method", "CMA", "--out", str(out), "--no-video"])
    log = res.stderr.strip().splitlines()
    assert log[0].startswith("trial    0  round 0  demonstration")
    finished = [line for line in log if line.endswith("| finished")]
    assert len(finished) == 1 and finished[0].startswith("run CMA | trials 99/99 | failures ")
    assert "best R +0." in finished[0]
    assert res.stdout.startswith("run 1: CMA on synthetic, seed 0: 99 trials") and "learner's best: return" in res.stdout

    res = _invoke(["run", "synthetic", "--method", "CMA", "--out", str(out), "--no-video", "--quiet", "--json"])
    assert res.stderr == ""
    summary = json.loads(res.stdout)
    assert set(summary) >= {"task", "method", "seed", "best_theta", "best_return", "trials", "failures",
                            "run_id", "store", "files", "versions"}
    assert summary["run_id"] == 2 and summary["trials"] == 99

    store = str(out / "run.corl")
    listed = json.loads(_invoke(["runs", "--store", store, "--json"]).stdout)
    assert [r["id"] for r in listed["runs"]] == [1, 2] and listed["runs"][0]["method"] == "CMA"
    status = json.loads(_invoke(["status", "--store", store, "--json"]).stdout)
    assert status["id"] == 2 and status["trials"] == 99 and status["pending"] == 0
    assert status["failures"] == summary["failures"] and status["best"]["return"] >= summary["best_return"]
    res = _invoke(["report", "--store", store, "--out", str(tmp_path / "pages"), "--run", "2", "--no-video",
                   "--quiet", "--json"])
    assert res.stderr == "" and json.loads(res.stdout)["pages"] == [str(tmp_path / "pages" / "run_2.html")]


def test_choose_mode():
    terminal = Console(file=io.StringIO(), force_terminal=True)
    pipe = Console(file=io.StringIO(), force_terminal=False)
    assert choose_mode(console=terminal) is Mode.LIVE
    assert choose_mode(console=pipe) is Mode.LOG
    assert choose_mode(log=True, console=terminal) is Mode.LOG
    assert choose_mode(quiet=True, log=True, console=terminal) is Mode.QUIET


def test_live_display_shows_done_failures_and_best_return():
    buffer = io.StringIO()
    console = Console(file=buffer, force_terminal=True, width=160, color_system=None)
    with Tracker(Mode.LIVE, "run", console=console) as tracker:
        tracker.update("trials", done=1, failures=0, ret=0.25, note="round 0 demonstration")
        tracker.update("trials", done=2, failures=1, note="round 0 optimization")
        tracker.update("trials", done=3, failures=0, ret=-0.5, note="round 1 reinforcement")
    text = buffer.getvalue()
    assert "3/?" in text and "failures 1" in text and "best R +0.2500" in text and "round 1 reinforcement" in text


@pytest.mark.parametrize("mode", [Mode.LOG, Mode.QUIET])
def test_log_lines_and_quiet(mode):
    buffer = io.StringIO()
    with Tracker(mode, "bench door", console=Console(file=buffer, width=200)) as tracker:
        tracker.add_stage("CORL+PIBU", total=2)
        tracker.update("CORL+PIBU", advance=1, failures=3, ret=0.4, note="seed 0: 3/6 failed")
        tracker.update("safe region", done=5, total=9, note="2 safe so far")
        tracker.message("writing ...")
    lines = buffer.getvalue().splitlines()
    if mode is Mode.QUIET:
        assert lines == []
        return
    assert lines[0].startswith("bench door | CORL+PIBU 1/2 | failures 3 | best R +0.4000 | ")
    assert lines[0].endswith(" | seed 0: 3/6 failed")
    assert lines[1].startswith("bench door | safe region 5/9 | ") and "failures" not in lines[1]
    assert lines[2] == "writing ..."


def test_protect_stdout_sends_stray_prints_to_stderr(capsys):
    with Tracker(Mode.QUIET, "run", protect_stdout=True):
        print("a task that talks")
    captured = capsys.readouterr()
    assert captured.out == "" and "a task that talks" in captured.err


@pytest.mark.parametrize("noise", [[], ["--return-noise", "0.05", "--flip", "0.05"]], ids=["clean", "noisy"])
def test_status_and_summary_name_the_same_learners_best_and_the_best_observed_beside_it(tmp_path, noise):
    out, store = tmp_path / "run", str(tmp_path / "s.corl")
    _invoke(["run", "synthetic", "--method", "CORL", "--out", str(out), "--store", store, "--no-video", "-q",
             *noise])
    summary = json.loads((out / "summary.json").read_text())
    status = json.loads(_invoke(["status", "--store", store, "--json"]).stdout)
    best = status["best"]
    assert best["theta"] == pytest.approx(summary["best_theta"], rel=1e-12)
    assert best["return"] == pytest.approx(summary["best_return"], rel=1e-12)
    assert best["trial"] == summary["best_trial"] and best["return_std"] == summary["best_return_std"]
    assert status["best_observed"]["return"] == pytest.approx(summary["best_observed"]["return"], rel=1e-12)
    assert status["best_observed"]["return"] >= best["return"] - 1e-12  # the highest reading, by its name
    text = _invoke(["status", "--store", store]).stdout
    assert "learner's best: return" in text and "best observed: reading" in text and "best return" not in text


def test_ask_run_and_serve_give_a_new_run_the_same_default_method(tmp_path):
    from corl.cli.learn import _default_method
    from corl.methods import DEFAULT_METHOD

    assert _default_method("synthetic") == "CORL+PIBU" and _default_method("door") == "CORL+PIBU"
    assert _default_method("examples.planar_button:make_task") == DEFAULT_METHOD == "CORL"
    store = str(tmp_path / "s.corl")
    _invoke(["ask", "--task", "examples.planar_button:make_task", "--store", store, "--raw"])
    assert json.loads(_invoke(["status", "--store", store, "--json"]).stdout)["method"] == "CORL"
