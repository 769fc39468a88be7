"""``corl bench contexts``: four methods, a truth never below what they saw, per-trial logs, skipped scenes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from corl.errors import InputError
from corl.experiments.contexts import METHODS, bench_contexts, contexts_table, parse_truth


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    return bench_contexts("synthetic-context", train_count=3, test_count=3, seed=0, out=out, budget=30)


def test_every_method_is_scored_against_the_closed_form_best(synthetic):
    assert set(synthetic["methods"]) == set(METHODS)
    for t in synthetic["test"]:
        assert t["truth"] == "task's best_return()" and t["best"] == pytest.approx(1.0)
        for name in METHODS:
            r = t[name]
            log = r["log"]
            assert len(log["success"]) == len(log["return"]) == len(log["theta"]) == r["trials"]
            assert r["failures"] == sum(not s for s in log["success"])
            assert r["trials_to_95"] <= r["trials_to_99"] <= max(r["trials"], 30)
            returns = [x for x, s in zip(log["return"], log["success"]) if s]
            assert max(returns, default=-np.inf) <= t["best"] + 1e-9
            if r["reached_95"]:  # the trial counted as reaching 95 % does reach it
                assert log["success"][r["trials_to_95"] - 1] and log["return"][r["trials_to_95"] - 1] >= 0.95
        # `nearest` is the first trial of nearest+CORL: the same motion, run once
        assert t["nearest"]["log"]["success"] == t["nearest+CORL"]["log"]["success"][:1]
    table = contexts_table(synthetic)
    assert all(name in table for name in METHODS) and "to 99%" in table


def test_the_best_is_never_below_what_a_method_saw(tmp_path):
    payload = bench_contexts("bench_fixtures:low_truth", train_count=2, test_count=2, seed=0, out=tmp_path, budget=30)
    for t in payload["test"]:
        seen = [x for name in METHODS for x, s in zip(t[name]["log"]["return"], t[name]["log"]["success"]) if s]
        assert t["best_truth"] == 0.5 and max(seen) > 0.5
        assert t["best"] == pytest.approx(max(seen)) and t["truth_below_seen"]
        assert all(t[name]["final_return_ratio"] <= 1.0 + 1e-12 for name in METHODS)


def test_a_scene_without_demonstration_is_named_skipped_and_counted(tmp_path):
    payload = bench_contexts("bench_fixtures:no_demo_above", train_count=3, test_count=4, seed=0, out=tmp_path,
                             budget=20)
    skipped = [t for t in payload["test"] if "skipped" in t]
    kept = [t for t in payload["test"] if "skipped" not in t]
    assert skipped and kept, [t["context"] for t in payload["test"]]  # seed 0 draws scenes on both sides of 0.3
    assert all(t["context"][0] > 0.3 and "no recording" in t["skipped"] for t in skipped)
    assert payload["skipped"]["test"] == len(skipped)
    assert payload["methods"]["contextual"]["contexts"] == len(kept)
    table = contexts_table(payload)
    assert sum(line.startswith("skipped test context") for line in table.splitlines()) == len(skipped)
    json.dumps(payload, default=float)  # contexts.json can hold it


@pytest.mark.parametrize("text, expected", [("auto", ("auto", 64)), ("task", ("task", 64)), ("grid:400", ("grid", 400))])
def test_truth_spellings(text, expected):
    assert parse_truth(text) == expected


@pytest.mark.parametrize("text", ["grid", "grid:1", "grid:x", "sweep:10", "", "grid:-5"])
def test_a_bad_truth_is_refused(text):
    with pytest.raises(InputError, match="--truth"):
        parse_truth(text)


def test_cli_refuses_a_bad_truth_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from corl.cli import app

    result = CliRunner().invoke(app, ["bench", "contexts", "synthetic-context", "--truth", "grid:x", "--out",
                                      str(tmp_path / "o")])
    assert result.exit_code == 2
    assert "--truth" in result.output and "Traceback" not in result.output
    assert not (tmp_path / "o").exists()


def test_the_skill_settings_reach_training_and_test(tmp_path):
    payload = bench_contexts("synthetic-context", train_count=2, test_count=1, seed=0, out=tmp_path, budget=10,
                             skill={"p_min": 0.5})
    assert payload["skill"] == {"p_min": 0.5}
    from corl.store import RunStore

    with RunStore(tmp_path / "train.corl", create=False, readonly=True) as db:
        runs = db.runs()
    assert "skill" not in runs[0].config and runs[1].config["skill"] == {"p_min": 0.5}


def test_cli_refuses_a_bad_p_min_in_one_line(tmp_path):
    from typer.testing import CliRunner

    from corl.cli import app

    result = CliRunner().invoke(app, ["bench", "contexts", "synthetic-context", "--p-min", "1.5", "--out",
                                      str(tmp_path / "o")])
    assert result.exit_code == 2 and "--p-min" in result.output and "Traceback" not in result.output


def test_a_scene_whose_ground_truth_raises_is_named_and_skipped(tmp_path):
    payload = bench_contexts("bench_fixtures:no_truth_above", train_count=2, test_count=4, seed=0, out=tmp_path,
                             budget=10)
    skipped = [t for t in payload["test"] if "skipped" in t]
    assert skipped and len(skipped) < 4 and all(t["context"][0] > 0.3 for t in skipped)
    assert all("ground truth raised ValueError: no theta of the grid" in t["skipped"] for t in skipped)
    assert payload["skipped"]["test"] == len(skipped)
