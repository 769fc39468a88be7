import json

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.experiments.synthetic import aggregate, run_one, starts, sweep
from corl.methods import PAPER_FIG1, make_method
from corl.tasks.synthetic import SyntheticTask


def test_every_method_runs_and_direct_methods_search_w():
    W = starts(1, 0)
    for name in list(PAPER_FIG1) + ["CORL+PIBU(literal)"]:
        r = run_one(name, 0, W[0], 0)
        assert r.rollouts >= 2 and r.failures <= r.rollouts
        assert r.best_w is not None


def test_sweep_is_deterministic_and_table_has_fields():
    a = sweep(["CORL+PIBU", "CMA"], 2, seed=1, jobs=1)
    b = sweep(["CORL+PIBU", "CMA"], 2, seed=1, jobs=2)
    assert [(r.method, r.start, r.failures, r.rollouts, r.best_w) for r in a] == \
           [(r.method, r.start, r.failures, r.rollouts, r.best_w) for r in b]
    table = aggregate(a, ["CORL+PIBU", "CMA"])
    assert set(table["CMA"]) >= {"starts", "found", "failures_mean", "failures_std", "max_dist_mean",
                                 "max_dist_std", "rollouts_mean", "seconds"}


def test_unknown_method_is_a_clear_error():
    with pytest.raises(Exception, match="unknown .*method"):
        make_method("CORL+MAGIC", SyntheticTask())


def test_cli_bench_and_run(tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["bench", "synthetic", "--starts", "2", "--seed", "0", "--out", str(tmp_path),
                              "--methods", "CORL+PIBU,PoWER", "--jobs", "1", "--quiet"])
    assert res.exit_code == 0, res.output
    data = json.loads((tmp_path / "synthetic.json").read_text())
    assert set(data["methods"]) == {"CORL+PIBU", "PoWER"} and "numpy" in data["versions"]
    assert "CORL+PIBU" in res.output and "paper" in res.output
    res = runner.invoke(app, ["run", "synthetic", "--seed", "1", "--out", str(tmp_path / "run"), "--quiet"])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["success"] and summary["J_final"] < summary["J_initial"]
    assert set(summary) >= {"task", "method", "seed", "best_theta", "best_return", "trials", "failures",
                            "seconds", "versions"}
    res = runner.invoke(app, ["bench", "synthetic", "--starts", "1", "--methods", "NOPE", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "unknown method" in res.output
    res = runner.invoke(app, ["run", "no.such.module:make", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "cannot import" in res.output
