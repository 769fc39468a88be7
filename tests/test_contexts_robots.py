"""``corl bench contexts --robots K`` (corl.experiments.context_training) and copying runs between
stores (corl.store.copy): training scenes in waves of K, each scene of a wave learning from the runs
of the waves before it only, in its own process and store, gathered into train.corl in order.

The family is ``synthetic-context``: a scene learned from its demonstration takes ~450 closed-form
trials (~2 s), one learned from a skill a few.
"""

from __future__ import annotations

import numpy as np
import pytest
from cli_refusal import refuse

from corl.errors import InputError
from corl.experiments.context_training import _learn_alone, _task, _train_waves, check_robots, train, waves
from corl.experiments.contexts import draw_contexts
from corl.problem import Outcome, Proposal
from corl.store import RunStatus, RunStore, StoreError
from corl.store.copy import copy_runs

SPEC = "synthetic-context"


def contexts(count: int) -> np.ndarray:
    """The bench's training contexts for seed 0: the demonstration's, then a Latin hypercube."""
    task = _task(SPEC, 0)
    spread = draw_contexts(task.context_bounds, count - 1, np.random.default_rng([0, 22]), spread=True)
    return np.vstack([np.asarray(task.context, dtype=float)[None], spread])


def runs_of(path):
    with RunStore(path, create=False, readonly=True) as db:
        return [(info, db.trials(info.id), db.best(info.id)) for info in db.runs()]


def same_trials(a, b) -> bool:
    """Two runs' trials bit for bit: w and theta bytes, step, round, outcomes and their times."""
    return len(a) == len(b) and all(
        x.proposal.w.tobytes() == y.proposal.w.tobytes() and x.proposal.theta.tobytes() == y.proposal.theta.tobytes()
        and (x.proposal.step, x.proposal.round, x.proposed_at) == (y.proposal.step, y.proposal.round, y.proposed_at)
        and (x.outcome is None) == (y.outcome is None)
        and (x.outcome is None or (x.outcome.success, x.outcome.return_, x.outcome.info)
             == (y.outcome.success, y.outcome.return_, y.outcome.info))
        for x, y in zip(a, b))


def same_learning(a, b) -> bool:
    """Two runs' trials bit for bit, their times left out (learned at different moments)."""
    return len(a) == len(b) and all(
        x.proposal.w.tobytes() == y.proposal.w.tobytes() and x.proposal.theta.tobytes() == y.proposal.theta.tobytes()
        and (x.outcome.success, x.outcome.return_, x.outcome.info) == (y.outcome.success, y.outcome.return_, y.outcome.info)
        for x, y in zip(a, b))


@pytest.fixture(scope="module")
def two_robots(tmp_path_factory):
    """Four training scenes learned by two robots: wave 1 (scenes 1, 2), then wave 2 (scenes 3, 4)."""
    folder = tmp_path_factory.mktemp("robots")
    rows = train(SPEC, 0, contexts(4), folder / "train.corl", robots=2)
    return folder, rows


# -- copying runs ------------------------------------------------------------------------------------
def _stored_run(db: RunStore, robots: int = 1) -> int:
    config = {"context": [0.25], "robots": robots} if robots > 1 else {"context": [0.25]}
    rid = db.create_run(task="t", method="CORL", seed=3, config=config, versions={"corl": "x"})
    rng = np.random.default_rng(rid)
    for i in range(4):
        db.add_proposal(rid, Proposal(i, rng.normal(size=5), rng.normal(size=2), "step 2", 1))
        if i < 3:
            db.add_outcome(rid, i, Outcome(i != 1, None if i == 1 else float(rng.normal()), {"i": i, "x": [0.5]}))
    db.set_best(rid, {"theta": [0.1, 0.2], "return": 0.7})
    return rid


def test_a_copied_run_holds_the_source_run_bit_for_bit(tmp_path):
    with RunStore(tmp_path / "a.corl") as a:
        first, second = _stored_run(a), _stored_run(a)
        a.set_status(first, RunStatus.FINISHED)
    with RunStore(tmp_path / "b.corl") as b:
        _stored_run(b)  # the target holds a run already: the copies get its next ids
        with RunStore(tmp_path / "a.corl", create=False, readonly=True) as a:
            assert copy_runs(b, [(a, second), (a, first)]) == [2, 3]
    source, target = runs_of(tmp_path / "a.corl"), runs_of(tmp_path / "b.corl")
    for (info, trials, best), (copy, copied, copied_best) in zip([source[1], source[0]], target[1:]):
        assert (copy.created, copy.task, copy.method, copy.seed, copy.config, copy.versions, copy.status,
                copy.n_trials, copy.n_told) == (info.created, info.task, info.method, info.seed, info.config,
                                                info.versions, info.status, info.n_trials, info.n_told)
        assert same_trials(trials, copied) and copied[-1].outcome is None  # the pending trial stays pending
        assert copied_best == best
    with RunStore(tmp_path / "b.corl") as b:  # the copy goes on as the source would: its pending trial is told
        b.add_outcome(2, 3, Outcome(True, 1.0, {}))


def test_copying_keeps_the_order_of_tells_of_a_run_with_several_robots(tmp_path):
    with RunStore(tmp_path / "a.corl") as a:
        rid = a.create_run(task="t", method="CORL", seed=0, config={"robots": 2})
        for i in range(2):
            a.add_proposal(rid, Proposal(i, np.full(3, i + 0.5), np.zeros(2), "step 1", 0))
        a.add_outcome(rid, 1, Outcome(True, 0.5, {}))
        a.add_outcome(rid, 0, Outcome(False, None, {}))
        with RunStore(tmp_path / "b.corl") as b:
            (new,) = copy_runs(b, [(a, rid)])
            assert b.told_order(new) == a.told_order(rid) == [1, 0]
            assert b.pattern(new) == a.pattern(rid) == "aatt"


def test_a_copy_of_a_missing_run_writes_nothing(tmp_path):
    with RunStore(tmp_path / "a.corl") as a:
        rid = _stored_run(a)
    with RunStore(tmp_path / "b.corl") as b, RunStore(tmp_path / "a.corl", create=False, readonly=True) as a:
        with pytest.raises(StoreError, match="has no run 7"):
            copy_runs(b, [(a, rid), (a, 7)])
        assert b.runs() == []


# -- waves -------------------------------------------------------------------------------------------
def test_waves_take_the_contexts_k_at_a_time_in_order():
    assert [list(w) for w in waves(5, 2)] == [[0, 1], [2, 3], [4]]
    assert [list(w) for w in waves(3, 1)] == [[0], [1], [2]]
    assert [list(w) for w in waves(3, 8)] == [[0, 1, 2]]


def test_a_scene_of_wave_2_learned_from_exactly_the_runs_of_wave_1(two_robots):
    folder, rows = two_robots
    stored = runs_of(folder / "train.corl")
    assert [info.id for info, _, _ in stored] == [1, 2, 3, 4]
    assert np.allclose([info.config["context"] for info, _, _ in stored], contexts(4))  # in the contexts' order
    assert all(info.status is RunStatus.FINISHED for info, _, _ in stored)
    wave1 = {str(info.id): info.n_told for info, _, _ in stored[:2]}
    assert [info.config["learned_from"] for info, _, _ in stored] == [{}, {}, wave1, wave1]
    assert [r["start"] for r in rows] == ["demonstration", "demonstration", "skill", "skill"]
    assert [r["trials"] for r in rows] == [len(trials) for _, trials, _ in stored]
    assert [p.name for p in folder.iterdir()] == ["train.corl"]  # the robots' own stores are gone


def test_the_copied_run_is_the_robots_run(two_robots, tmp_path):
    """Scene 3 learned again alone, from wave 1 of train.corl: the same trials as its copy there."""
    folder, _ = two_robots
    stored = runs_of(folder / "train.corl")
    info, trials, _ = stored[2]
    row = _learn_alone(SPEC, 0, info.config["context"], str(folder / "train.corl"), info.config["learned_from"],
                       None, str(tmp_path / "alone.corl"), 0.0)
    ((alone, again, _),) = runs_of(tmp_path / "alone.corl")
    assert row["trials"] == len(trials) and alone.config == info.config
    assert same_learning(trials, again)


def test_resume_keeps_a_finished_wave_and_learns_the_next_from_it(two_robots, tmp_path):
    folder, rows = two_robots
    store = tmp_path / "train.corl"
    train(SPEC, 0, contexts(4)[:2], store, robots=2)  # wave 1 only (a study stopped after it)
    before = runs_of(store)
    again = train(SPEC, 0, contexts(4), store, robots=2)
    after = runs_of(store)
    assert [i.created for i, _, _ in after[:2]] == [i.created for i, _, _ in before]  # wave 1 kept, not learned again
    assert [i.config for i, _, _ in after] == [i.config for i, _, _ in runs_of(folder / "train.corl")]
    assert all(same_learning(a, b) for (_, a, _), (_, b, _) in zip(after, runs_of(folder / "train.corl")))
    assert [r["trials"] for r in again] == [r["trials"] for r in rows]
    with RunStore(store) as db:  # an unfinished run of a wave is continued where it stands
        db.set_status(4, RunStatus.RUNNING)
    train(SPEC, 0, contexts(4), store, robots=2)
    final = runs_of(store)
    assert len(final) == 4 and final[3][0].status is RunStatus.FINISHED and same_trials(final[3][1], after[3][1])


def test_one_robot_through_the_waves_is_the_run_in_turn(tmp_path):
    """K = 1 is today's training (each scene from every run before it); waves of one robot in worker
    processes with copies give the same trials bit for bit."""
    cs = contexts(3)
    train(SPEC, 0, cs, tmp_path / "turn.corl", robots=1)
    _train_waves(_task(SPEC, 0), SPEC, 0, cs, tmp_path / "waves.corl", None, None, 1, 0.0)
    turn, wave = runs_of(tmp_path / "turn.corl"), runs_of(tmp_path / "waves.corl")
    assert [i.config["learned_from"] for i, _, _ in turn] == [{}, {"1": turn[0][0].n_told},
                                                               {"1": turn[0][0].n_told, "2": turn[1][0].n_told}]
    assert [i.config for i, _, _ in wave] == [i.config for i, _, _ in turn]
    assert all(same_learning(a, b) for (_, a, _), (_, b, _) in zip(turn, wave))


# -- refusals ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("robots, seconds", [(0, 0.0), (65, 0.0), (True, 0.0), (2.5, 0.0), (2, -1.0),
                                             (2, float("nan")), (2, float("inf"))])
def test_bad_robots_or_seconds_are_refused(robots, seconds):
    with pytest.raises(InputError, match="--robots|--trial-seconds"):
        check_robots(robots, seconds)


@pytest.mark.parametrize("args, message", [
    (["--robots", "0"], "--robots must be an integer in [1, 64], got 0"),
    (["--robots", "-3"], "--robots must be an integer in [1, 64], got -3"),
    (["--trial-seconds", "-0.5"], "--trial-seconds must be a number of seconds in [0, 3600], got -0.5"),
    (["--trial-seconds", "nan"], "--trial-seconds must be a number of seconds"),
])
def test_cli_refuses_bad_robots_in_one_line(args, message, tmp_path):
    refuse(["bench", "contexts", SPEC, "--train", "2", "--test", "1", "--out", str(tmp_path / "out"), *args], message)
    assert not (tmp_path / "out").exists()


def test_contexts_json_records_the_robots_and_their_time(tmp_path):
    from corl.experiments.contexts import bench_contexts

    payload = bench_contexts(SPEC, train_count=2, test_count=1, seed=0, out=tmp_path, budget=5, jobs=1, robots=2,
                             trial_seconds=0.001)
    assert (payload["robots"], payload["trial_seconds"]) == (2, 0.001)
    assert 0 < payload["train_seconds"] <= payload["wall_seconds"]
    assert [r["start"] for r in payload["train"]] == ["demonstration", "demonstration"]  # one wave of two


def test_ctrl_c_ends_the_robots_at_once(tmp_path):
    """Interrupted in wave 1 (scenes of ~450 trials of 0.05 s each), the study ends in seconds, not when
    the robots' scenes would; their stores go with them."""
    import signal
    import subprocess
    import sys
    import time

    script = ("import signal, sys, numpy as np; signal.signal(signal.SIGINT, signal.default_int_handler); "
              "from pathlib import Path; from corl.experiments.context_training import train; "
              f"train({SPEC!r}, 0, np.array([[0.0], [0.5]]), Path(sys.argv[1]) / 'train.corl', robots=2, "
              "trial_seconds=0.05)")
    child = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)], stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)
    child.send_signal(signal.SIGINT)
    t0 = time.perf_counter()
    _, err = child.communicate(timeout=60)
    assert child.returncode != 0 and "KeyboardInterrupt" in err
    assert time.perf_counter() - t0 < 5.0  # a scene alone takes ~25 s here
    assert list(tmp_path.iterdir()) == []  # nothing stored: no wave was done
