"""The skill's settings and a run's scene from the shell (issue 33, item 4): ``--p-min`` on ``corl run``,
``corl ask`` and ``corl policy`` (:func:`corl.cli.skill.skill_settings`), ``corl sweep --context``,
the scene in ``corl runs``, ``corl status`` and ``corl export`` (``--all``: every run in one table).

The store holds two finished runs of ``synthetic-context`` (c = -0.5 from its demonstration, then
c = 0.5 from the skill, with ``--p-min 0.8``); about 2 s.
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from cli_refusal import copy_of, refuse, state
from typer.testing import CliRunner

from corl.cli import app
from corl.store import RunStore

runner = CliRunner()


def corl(*args) -> str:
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, (args, res.output, res.exception)
    return res.stdout


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    folder = tmp_path_factory.mktemp("shell")
    corl("run", "synthetic-context", "--context=-0.5", "--store", folder / "ctx.corl", "--out", folder / "a", "-q")
    corl("run", "synthetic-context", "--context", "0.5", "--p-min", "0.8", "--store", folder / "ctx.corl",
         "--out", folder / "b", "-q")
    return folder


@pytest.fixture
def workdir(template, tmp_path, monkeypatch):
    return copy_of(template, tmp_path, monkeypatch)


def test_p_min_is_recorded_with_the_run_and_its_skill_is_rebuilt_with_it(template):
    from corl.session import StoredRun
    from corl.tasks.registry import load_task

    with RunStore(template / "ctx.corl", readonly=True, create=False) as db:
        infos = db.runs()
        assert [i.config.get("skill") for i in infos] == [None, {"p_min": 0.8}]
        reopened = StoredRun.open(db, load_task("synthetic-context"), 2)
    assert reopened.learner.skill.p_min == 0.8  # the skill the run learned with, not the default 0.95


def test_policy_takes_p_min(workdir):
    doc = json.loads(corl("policy", "synthetic-context", "--store", "ctx.corl", "--context", "0", "--p-min", "0.6",
                          "--json", "--out", "p"))
    assert doc["p_min"] == 0.6
    assert sorted(p.name for p in (workdir / "p").iterdir()) == ["policy.json"]  # no reference(): policy.json only


RUN = ["run", "synthetic-context", "--store", "ctx.corl", "--out", "o", "-q"]
REFUSED = [
    ([*RUN, "--context", "0.1", "--p-min", "1"], "--p-min must be in (0, 1)"),
    ([*RUN, "--context", "0.1", "--p-min", "0"], "--p-min must be in (0, 1)"),
    ([*RUN, "--context", "0.1", "--p-min", "nan"], "--p-min must be a plain finite number"),
    ([*RUN, "--p-min", "0.9"], "add --context C"),
    ([*RUN, "--context", "0.5", "--resume", "--p-min", "0.9"], "--p-min 0.9 differs from the run being resumed"),
    (["ask", "--task", "synthetic-context", "--store", "ctx.corl", "--raw", "--p-min", "0.9"], "add --context C"),
    (["policy", "synthetic-context", "--store", "ctx.corl", "--context", "0", "--p-min", "-1"], "in (0, 1)"),
    (["sweep", "synthetic-context", "--grid", "5", "--out", "s", "--context", "1.5"], "outside the context box"),
    (["sweep", "synthetic", "--grid", "5", "--out", "s", "--context", "0"], "has no contexts"),
    (["export", "--store", "ctx.corl", "--out", "t.csv", "--all", "--run", "1"], "--all exports every run"),
]


@pytest.mark.parametrize("args, message", REFUSED, ids=[" ".join(a)[:70] for a, _ in REFUSED])
def test_refused_in_one_line_and_nothing_changes(workdir, args, message):
    before = state(workdir)
    refuse(args, message)
    assert state(workdir) == before


@pytest.mark.parametrize("c", [-0.8, 0.8])
def test_sweep_in_a_scene_finds_that_scenes_optimum(workdir, c):
    doc = json.loads(corl("sweep", "synthetic-context", "--grid", "81", f"--context={c}", "--out", "s", "--json",
                          "-q"))
    assert doc["context"] == [c]
    assert abs(doc["best"]["theta"][0] - 0.5 * c) < 0.05  # theta*(c) = 0.5 c, not the own scene's 0
    assert json.loads((workdir / "s" / "sweep.json").read_text())["context"] == [c]


def test_runs_and_status_show_each_runs_scene(workdir):
    table = corl("runs", "--store", "ctx.corl").splitlines()
    assert table[0].split()[-1] == "context"
    assert [row.split()[-1] for row in table[1:]] == ["-0.5", "0.5"]
    assert [r["context"] for r in json.loads(corl("runs", "--store", "ctx.corl", "--json"))["runs"]] == [[-0.5], [0.5]]
    assert "context 0.5" in corl("status", "--store", "ctx.corl").splitlines()[0]
    corl("ask", "--task", "synthetic", "--raw", "--store", "plain.corl", "--out", "t")
    assert corl("runs", "--store", "plain.corl").splitlines()[1].split()[-1] == "-"


def test_export_all_runs_with_their_scenes(workdir):
    corl("export", "--store", "ctx.corl", "--out", "all.csv", "--all")
    rows = list(csv.DictReader(open(workdir / "all.csv", newline="")))
    assert list(rows[0])[:5] == ["run", "index", "step", "round", "context_0"]
    with RunStore(workdir / "ctx.corl", readonly=True, create=False) as db:
        counts = [r.n_trials for r in db.runs()]
    assert [sum(r["run"] == str(i) for r in rows) for i in (1, 2)] == counts
    assert {r["context_0"] for r in rows if r["run"] == "1"} == {"-0.5"}
    assert {r["context_0"] for r in rows if r["run"] == "2"} == {"0.5"}
    with np.load(workdir / "all.w.npz", allow_pickle=False) as npz:
        assert npz["run"].tolist() == [int(r["run"]) for r in rows] and len(npz["w"]) == len(rows)
    corl("export", "--store", "ctx.corl", "--out", "one.csv", "--run", "1")
    one = list(csv.DictReader(open(workdir / "one.csv", newline="")))
    assert "run" not in one[0] and len(one) == counts[0] and one[0]["context_0"] == "-0.5"
