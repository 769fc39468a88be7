"""One server, many scenes (issue 33, item 5): a robot says its scene when it asks
(``POST /ask {"context": [...]}``, ``Client.ask(context=...)``); the server learns there from the
store as ``corl ask --context`` does; one trial is pending at a time, across scenes; bad contexts
are 400 with one line; ``/status`` lists every run with its scene.

The task is ``synthetic-context`` (theta*(c) = 0.5 c); the store starts with one finished run in
c = -0.5 (~1 s).
"""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from corl.client import Client  # noqa: E402
from corl.errors import InputError, StateError  # noqa: E402
from corl.serve import background  # noqa: E402
from corl.session import StoredRun  # noqa: E402
from corl.store import RunStore  # noqa: E402
from corl.tasks.registry import load_task  # noqa: E402

TASK = "synthetic-context"


@pytest.fixture
def store(tmp_path):
    """A store with one finished run of synthetic-context in c = -0.5."""
    task = load_task(TASK)
    path = tmp_path / "ctx.corl"
    with RunStore(path) as db:
        StoredRun.new(task, task_spec=TASK, method="CORL", seed=0, context=[-0.5], learned_from=db).attach(db).run(task)
    return path


def _post(url: str, path: str, body: dict):
    request = urllib.request.Request(url + path, data=json.dumps(body).encode(), method="POST",
                                     headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(request, timeout=60) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def test_a_robot_learns_in_its_scene_from_what_the_store_learned(store):
    scene = load_task(TASK).with_context(np.array([0.4]))
    with background(store, TASK) as url:
        c = Client(url, raw=True)
        first = c.ask(context=[0.4])
        assert first.run == 2 and first.index == 0 and first.context.tolist() == [0.4]
        assert first.step == "skill"  # started from the skill learned in c = -0.5, not the demonstration
        trials = 0
        while not c.done:
            trial = c.ask(context=[0.4])
            c.tell(scene.rollout(trial.w))
            trials += 1
        status, best = c.status(), c.best
    assert status["context"] == [0.4] and status["run"] == 2
    assert abs(best.theta[0] - 0.2) < 0.05  # theta*(0.4) = 0.2, learned in that scene
    assert [(r["run"], r["context"], r["status"]) for r in status["runs"]] == [
        (1, [-0.5], "finished"), (2, [0.4], "finished")]
    with RunStore(store, readonly=True) as db:
        run, first_run = db.run(2), db.run(1)
    assert run.config["contextual"] and run.config["learned_from"] == {"1": first_run.n_told}
    assert run.n_told == trials


def test_one_trial_out_at_a_time_and_a_left_scene_goes_on_where_it_stopped(store):
    base = load_task(TASK)
    with background(store, TASK) as url:
        c = Client(url, raw=True)
        a = c.ask(context=[0.3])
        with pytest.raises(StateError, match=r"trial 0 of run 2 \(context \[0.3\]\) is pending"):
            c.ask(context=[-0.3])
        assert c.ask().index == a.index and c.ask(context=[0.3]).run == a.run  # the pending trial again
        c.tell(base.with_context(np.array([0.3])).rollout(a.w))
        b = c.ask(context=[-0.3])  # no trial pending: the robot moved; run 2 stays unfinished
        assert (b.run, b.index, b.context.tolist()) == (3, 0, [-0.3])
        c.tell(base.with_context(np.array([-0.3])).rollout(b.w))
        back = c.ask(context=[0.3])  # back in c = 0.3: run 2 goes on, it is not started again
        assert (back.run, back.index) == (2, 1)
        with pytest.raises(StateError, match="already told"):  # trial 0 of run 2 was told otherwise
            c.tell(False, None, trial=0)


def test_a_tell_repeated_after_a_scene_change_is_answered_again(store):
    base = load_task(TASK)
    with background(store, TASK) as url:
        c = Client(url, raw=True)
        a = c.ask(context=[0.3])
        outcome = base.with_context(np.array([0.3])).rollout(a.w)
        c.tell(outcome)
        c.ask(context=[-0.3])
        status, again = _post(url, "/tell", {"trial": 0, "run": a.run, "success": outcome.success,
                                             "return": outcome.return_})
        assert status == 200 and again["repeated"] and again["run"] == a.run
        status, other = _post(url, "/tell", {"trial": 0, "run": a.run, "success": not outcome.success,
                                             "return": None if outcome.success else 0.5})
        assert status == 409 and "not pending" in other["error"]


BAD = [({"raw": True, "context": [1.5]}, "outside the context box"),
       ({"raw": True, "context": [0.1, 0.2]}, "has 2 numbers"),
       ({"raw": True, "context": "0.1"}, "must be a list of 1 number"),
       ({"raw": True, "context": [True]}, "must be a list of 1 number")]


@pytest.mark.parametrize("body, message", BAD, ids=[m for _, m in BAD])
def test_a_bad_context_is_400_in_one_line_and_changes_nothing(store, body, message):
    with background(store, TASK) as url:
        status, answer = _post(url, "/ask", body)
        after = Client(url).status()
    assert status == 400 and message in answer["error"] and "\n" not in answer["error"]
    assert after["run"] == 1 and len(after["runs"]) == 1  # no run was started


def test_a_task_without_contexts_refuses_a_context(tmp_path):
    with background(tmp_path / "s.corl", "synthetic") as url:
        status, answer = _post(url, "/ask", {"raw": True, "context": [0.0]})
        with pytest.raises(InputError, match="has no contexts"):
            Client(url, raw=True).ask(context=[0.0])
        assert Client(url).status()["context"] is None
    assert status == 400 and "has no contexts" in answer["error"]


def test_the_client_checks_a_context_before_sending(store):
    with background(store, TASK) as url:
        with pytest.raises(InputError, match="finite"):
            Client(url, raw=True).ask(context=[float("nan")])
        with pytest.raises(InputError, match="must be numbers"):
            Client(url, raw=True).ask(context=["a"])


@pytest.mark.slow
def test_the_dashboard_shows_the_scene_of_each_run(store, tmp_path):
    from browser import Browser, chromium_path

    chromium_path()
    base = load_task(TASK)
    with background(store, TASK) as url:
        c = Client(url, raw=True)
        trial = c.ask(context=[0.3])
        c.tell(base.with_context(np.array([0.3])).rollout(trial.w))
        with Browser(tmp_path / "profile") as b:
            b.open(url + "/")
            title = "document.getElementById('title').textContent.includes('run 2 \\u00b7 context [0.3]')"
            assert b.wait_for(title, timeout=30), b.evaluate("document.body.innerText")[:500]
            scenes = b.evaluate("document.getElementById('scenes').textContent")
            assert "run 1 context [-0.5]" in scenes and "run 2 context [0.3] (1 told, running)" in scenes
            trial = c.ask(context=[-0.3])  # the robot moved: the page follows run 3, its table starts afresh
            moved = ("document.getElementById('title').textContent.includes('run 3 \\u00b7 context [-0.3]') && "
                     "document.querySelectorAll('#trial-rows tr').length == 1")
            assert b.wait_for(moved, timeout=10), b.evaluate("document.body.innerText")[:500]


def test_after_a_restart_a_left_scene_goes_on_from_the_store(store):
    base = load_task(TASK)
    with background(store, TASK) as url:
        c = Client(url, raw=True)
        for scene in ([0.3], [-0.3]):  # one trial in each: run 2 in 0.3 is left unfinished
            trial = c.ask(context=scene)
            c.tell(base.with_context(np.array(scene)).rollout(trial.w))
    with background(store, TASK) as url:  # restarted: it serves the latest run, 3
        c = Client(url, raw=True)
        assert c.status()["run"] == 3
        back = c.ask(context=[0.3])
    assert (back.run, back.index, back.context.tolist()) == (2, 1, [0.3])
