"""One store, many contexts, from the command line (corl/cli/learn.py, corl/cli/skill.py):
``corl run TASK --context C`` adds a run in scene C that starts from what the store's earlier runs
learned, ``corl ask/tell --context C`` does the same trial by trial, and ``corl policy`` deploys the
skill in any scene of the box with no trial. A refused command leaves every store byte for byte as
it was, its modification time included, and creates nothing.

The task is ``synthetic-context`` (one context c in [-1, 1], optimum theta*(c) = 0.5 c); its first
run (c = -0.5, ~650 trials of a closed-form task) and its second (c = 0.5) take about 2 s together.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_refusal import copy_of, refuse, state
from typer.testing import CliRunner

from corl.cli import app
from corl.store import RunStore

runner = CliRunner()

# synthetic-context with a joint trajectory: two "joints" moving linearly from 0 to w (corl.problem.HasReference)
REFTASK = """
import numpy as np
from corl.tasks.registry import load_task
from corl.tasks.synthetic import ContextualSyntheticTask

class WithReference(ContextualSyntheticTask):
    joint_names = ("x", "y")

    def with_context(self, c):
        return WithReference(self.w0, critical_distance=self.critical_distance, context=c)

    def reference(self, w, rate):
        t = np.arange(11) / rate
        return t, np.outer(t / t[-1], w)

def make(seed=0):
    return WithReference(load_task("synthetic-context", seed=seed).w0)
"""


def corl(*args: str) -> str:
    res = runner.invoke(app, [str(a) for a in args])
    assert res.exit_code == 0, (args, res.output, res.exception)
    return res.stdout


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    """``ctx.corl``: two finished runs of synthetic-context, in contexts -0.5 and 0.5 (summaries in a/, b/)."""
    folder = tmp_path_factory.mktemp("contexts")
    for name, c in (("a", "-0.5"), ("b", "0.5")):
        corl("run", "synthetic-context", "--context", c, "--store", folder / "ctx.corl", "--out", folder / name,
             "--no-video", "-q")
    (folder / "ctxref_task.py").write_text(REFTASK)
    return folder


@pytest.fixture
def workdir(template, tmp_path, monkeypatch):
    yield copy_of(template, tmp_path, monkeypatch)
    sys.modules.pop("ctxref_task", None)


def runs(store: Path):
    with RunStore(store, readonly=True, create=False) as db:
        return db.runs()


def test_two_contexts_share_one_store_and_the_second_starts_from_the_skill(template):
    infos = runs(template / "ctx.corl")
    assert [i.config["context"] for i in infos] == [[-0.5], [0.5]]
    assert all(i.config["contextual"] and i.method == "CORL" and i.status.value == "finished" for i in infos)
    first = json.loads((template / "a" / "summary.json").read_text())
    second = json.loads((template / "b" / "summary.json").read_text())
    assert first["context"] == [-0.5] and first["start"] == "demonstration"
    assert second["context"] == [0.5] and second["start"] == "skill"
    assert second["run_id"] == 2 and second["success"]
    assert abs(second["best_theta"][0] - 0.25) < 0.1  # theta*(0.5) = 0.25, learned in that scene
    assert second["trials"] < first["trials"]  # it started from what context -0.5 taught


@pytest.mark.parametrize("c", [0.0, 0.2, -0.3])
def test_policy_between_the_learned_contexts(workdir, c):
    before = state(workdir)
    out = corl("policy", "synthetic-context", "--store", "ctx.corl", "--context", str(c), "--out", "p")
    for word in ("context", "theta", "p_success", "R_mean ± R_std", "J", "nearest learned context", "policy.json"):
        assert word in out, (word, out)
    policy = json.loads((workdir / "p" / "policy.json").read_text())
    assert policy["context"] == [c] and policy["feasible"] is True
    assert abs(policy["theta"][0] - 0.5 * c) < 0.1, policy["theta"]  # theta*(c) = 0.5 c
    assert policy["nearest"] in ([-0.5], [0.5]) and policy["learned_contexts"] == [[-0.5], [0.5]]
    assert 0.0 <= policy["p_success"] <= 1.0 and len(policy["w"]) == 2
    assert sorted(p.name for p in (workdir / "p").iterdir()) == ["policy.json"]  # no reference(): no trajectory
    after = state(workdir)
    assert {k: v for k, v in after.items() if not k.startswith("p/")} == before  # the store was only read


def test_policy_json_and_trajectory_for_a_task_with_reference(workdir):
    doc = json.loads(corl("policy", "ctxref_task:make", "--store", "ctx.corl", "--context", "0.1", "--json",
                          "--rate", "50"))
    assert doc["files"] == {"policy": "policy.json", "csv": "policy.csv", "npz": "policy.npz"}  # beside the store
    assert doc["rate"] == 50.0 and abs(doc["theta"][0] - 0.05) < 0.1
    rows = (workdir / "policy.csv").read_text().splitlines()
    assert rows[0] == "t,x,y" and len(rows) == 12
    last = np.array([float(v) for v in rows[-1].split(",")])
    assert np.isclose(last[0], 10 / 50) and np.allclose(last[1:], doc["w"])
    npz = np.load(workdir / "policy.npz")
    assert np.allclose(npz["context"], [0.1]) and np.allclose(npz["theta"], doc["theta"])


def test_an_infeasible_policy_writes_nothing(workdir, monkeypatch):
    from corl.contexts.skill import Policy, Skill

    real = Skill.policy

    def infeasible(self, c):
        p = real(self, c)
        return Policy(p.context, p.w, p.theta, p.p_success, p.R_mean, p.R_std, p.J, p.nearest, False)

    monkeypatch.setattr(Skill, "policy", infeasible)
    before = state(workdir)
    refuse(["policy", "ctxref_task:make", "--store", "ctx.corl", "--context", "0.1", "--out", "p"],
           "does not satisfy the task's constraint h")
    assert state(workdir) == before and not (workdir / "p").exists()


RUN = ["run", "synthetic-context", "--out", "o", "--no-video", "-q", "--store", "ctx.corl"]
ASK = ["ask", "--task", "synthetic-context", "--raw", "--store", "ctx.corl"]
POLICY = ["policy", "synthetic-context", "--store", "ctx.corl", "--out", "p"]
BOX = "the context box of task 'synthetic-context': scene shift c in [-1, 1]"

REFUSED = [
    *[(cmd + ["--context", text], message) for cmd in (RUN, ASK, POLICY) for text, message in (
        ("0.1,0.2", "has 1 context coordinate"), ("nan", BOX), ("1e999", BOX), ("1.5", BOX), ("inf", BOX),
        ("", BOX), ("0.1,,0.2", "comma-separated"), ("0x1", BOX))],
    (["run", "synthetic", "--out", "o", "-q", "--store", "ctx.corl", "--context", "0.1"], "has no contexts"),
    (["ask", "--task", "synthetic", "--raw", "--store", "ctx.corl", "--context", "0.1"], "has no contexts"),
    (["policy", "synthetic", "--store", "ctx.corl", "--context", "0.1"], "has no contexts"),
    ([*RUN, "--context", "0.1", "--method", "CORL+CMA"], "learns with the CORL method"),
    ([*ASK, "--context", "0.1", "--method", "CMA"], "learns with the CORL method"),
    ([*RUN, "--context", "0.1", "--resume"], "learned in context 0.5, not in --context 0.1"),
    (["policy", "synthetic-context", "--store", "nothere.corl", "--context", "0.1"], "does not exist"),
    (["policy", "synthetic-context", "--store", ".", "--context", "0.1"], "is a folder"),
]


@pytest.mark.parametrize("args, message", REFUSED, ids=[" ".join(a)[:70] for a, _ in REFUSED])
def test_a_refused_context_leaves_every_file_as_it_was(workdir, args, message):
    before = state(workdir)
    refuse(args, message)
    assert state(workdir) == before  # bytes and mtime of the store; nothing new (o/, p/ removed while empty)


def test_policy_refuses_a_store_that_learned_no_context(workdir):
    corl("ask", "--task", "synthetic", "--raw", "--store", "plain.corl", "--out", "trials")
    before = state(workdir)
    refuse(["policy", "synthetic-context", "--store", "plain.corl", "--context", "0"],
           "needs at least one learned context")
    (workdir / "damaged.corl").write_bytes(b"\x13\x37" * 2048)
    refuse(["policy", "synthetic-context", "--store", "damaged.corl", "--context", "0"], "not a corl store")
    before["damaged.corl"] = state(workdir)["damaged.corl"]
    assert state(workdir) == before


def test_ask_and_tell_in_a_context_then_finish_it_with_run(workdir):
    first = json.loads(corl(*ASK, "--context", "0.1", "--out", "trials"))
    assert first["trial"] == 0 and abs(first["theta"][0] - 0.05) < 0.15  # the skill's policy for c = 0.1
    infos = runs(workdir / "ctx.corl")
    assert len(infos) == 3 and infos[-1].config["context"] == [0.1] and infos[-1].config["contextual"]
    before = state(workdir)
    refuse([*ASK, "--context", "-0.2"], "run 3 in ctx.corl (task 'synthetic-context', context 0.1) is not finished")
    assert state(workdir) == before
    told = json.loads(corl("tell", "--task", "synthetic-context", "--store", "ctx.corl", "--success", "yes",
                           "--return", "0.99"))
    assert told == {"trial": 0, "success": True, "return": 0.99, "done": False}
    again = json.loads(corl(*ASK, "--context", "0.1", "--out", "trials"))  # the same scene: the same run goes on
    assert again["trial"] == 1 and len(runs(workdir / "ctx.corl")) == 3
    corl("tell", "--task", "synthetic-context", "--store", "ctx.corl", "--success", "no")
    corl(*ASK, "--out", "trials")  # without --context: the latest run, as always
    corl(*RUN[:-1], "ctx.corl", "--resume", "--context", "0.1", "--out", "c")  # rolls out the rest in scene 0.1
    summary = json.loads((workdir / "c" / "summary.json").read_text())
    assert summary["run_id"] == 3 and summary["context"] == [0.1] and summary["start"] == "skill"
    assert abs(summary["best_theta"][0] - 0.05) < 0.1
    assert runs(workdir / "ctx.corl")[-1].status.value == "finished"


def test_ask_in_a_new_store_starts_from_the_scene_demonstration(workdir):
    doc = json.loads(corl("ask", "--task", "ctxref_task:make", "--store", "new.corl", "--context", "0.3",
                          "--out", "trials"))
    assert doc["step"] == "demonstration" and Path(doc["csv"]).is_file()
    info = runs(workdir / "new.corl")[0]
    assert info.config["context"] == [0.3] and info.config["contextual"] and info.method == "CORL"
