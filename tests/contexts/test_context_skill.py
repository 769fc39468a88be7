"""The skill across scenes on the synthetic family, whose optimum is known in closed form:
theta*(c) = 0.5 c and w*(c) = (1 + 0.2 c) (cos theta*, sin theta*)."""

import numpy as np
import pytest

from corl.contexts import Anchor, ContextData, ContextualCORL, Skill, plain_learner
from corl.errors import InputError
from corl.experiments.contexts import draw_contexts, train
from corl.experiments.synthetic import FOUND_TOLERANCE
from corl.loop import drive
from corl.tasks.registry import load_task
from corl.tasks.synthetic import ContextualSyntheticTask, SyntheticTask, optimum_of


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A skill trained on 8 contexts (the demonstration's, then a Latin hypercube), in one store."""
    task = load_task("synthetic-context", seed=0)
    contexts = np.vstack([[0.0], draw_contexts(task.context_bounds, 7, np.random.default_rng(5), spread=True)])
    store = tmp_path_factory.mktemp("skill") / "train.corl"
    rows = train("synthetic-context", 0, contexts, store)
    return task, store, contexts, rows


def test_the_learned_theta_star_of_c_is_the_closed_form_over_the_box(trained):
    """In each of 9 scenes across the box: the skill's first trial succeeds with no trial before it,
    near the optimum (it trades return for safety: within 0.2 rad), and learning in the scene from it
    ends within the paper's found tolerance of the closed form, with at most 3 failures."""
    task, store, _, rows = trained
    assert rows[0]["start"] == "demonstration" and all(r["start"] == "skill" for r in rows[1:])
    skill = Skill.load(store, task)
    assert len(skill.anchors) == 8
    for c in np.linspace(-1.0, 1.0, 9):
        theta, w = optimum_of(c)
        policy = skill.policy([c])
        assert policy.feasible and abs(policy.theta[0] - theta) < 0.2, (c, policy.theta)
        scene = task.with_context([c])
        assert scene.rollout(policy.w).success  # the first trial in that scene succeeds
        learner = ContextualCORL(task, [c], skill, seed=0)
        drive(learner, scene, max_trials=100)
        assert learner.done and sum(not o.success for _, o in learner.history) <= 3
        assert np.linalg.norm(learner.best.w - w) < FOUND_TOLERANCE, (c, learner.best.theta, theta)
        assert abs(learner.best.theta[0] - theta) < FOUND_TOLERANCE


def test_the_policy_unpacks_and_refuses_contexts_outside_the_box(trained):
    task, store, _, _ = trained
    skill = Skill.load(store, task)
    w, theta, p, r = skill.policy([0.3])
    assert w.shape == (2,) and theta.shape == (1,) and 0 < p < 1 and np.isfinite(r)
    for bad, says in (([1.2], "outside the bounds"), ([np.nan], "NaN"), ([0.1, 0.2], "shape"), ("a", "must be 1 number")):
        with pytest.raises(InputError, match=says) as err:
            skill.policy(bad)
        assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="at least one learned context"):
        Skill(task, ContextData.empty(1, 1), [])
    with pytest.raises(InputError, match="has no contexts"):
        Skill(SyntheticTask(), ContextData.empty(1, 1), [Anchor(np.zeros(1), np.ones(2), np.zeros(1), 1.0)])


def test_learning_in_a_new_context_starts_from_the_skill_and_stays_near_the_optimum(trained):
    task, store, _, _ = trained
    skill = Skill.load(store, task)
    c = np.array([-0.77])
    learner = ContextualCORL(task, c, skill, seed=0)
    drive(learner, task.with_context(c), max_trials=40)
    steps = [p.step for p, _ in learner.history]
    assert learner.start_kind == "skill" and steps[0] == "skill"
    assert [p.index for p, _ in learner.history] == list(range(len(steps)))
    assert learner.history[0][1].success and learner.done
    assert abs(learner.best.theta[0] - optimum_of(c[0])[0]) < FOUND_TOLERANCE


def test_a_failed_start_joins_the_data_and_the_next_start_is_tried():
    """An anchor whose motion fails in the new scene (theta far outside that scene's safe set):
    the skill's start fails, the learner records it and goes on from the next start."""
    task = ContextualSyntheticTask((0.5, 0.5))
    bad = 2.3  # safe at c = 1 (S: -1 < theta < 3), fails at c = -1 (S: -2 < theta < 2)
    w = np.array([np.cos(bad), np.sin(bad)]) * 1.2
    data = ContextData.empty(1, 1).add([bad], [1.0], True, -0.9)
    skill = Skill(task, data, [Anchor(np.array([1.0]), w, np.array([bad]), -0.9)])
    learner = ContextualCORL(task, [-1.0], skill, seed=0)
    drive(learner, task.with_context([-1.0]), max_trials=60)
    first = learner.history[0]
    assert not first[1].success
    assert learner.starts_tried >= 2 and learner.best is not None  # a later start succeeded
    starts = [p for p, _ in learner.history if p.step in ("skill", "demonstration")]
    assert len({p.theta.tobytes() for p in starts}) == len(starts)  # no start theta twice
    assert [p.index for p, _ in learner.history] == list(range(len(learner.history)))
    # a second run in that scene knows those failures: it never proposes one of those motions again
    failed = [p.w for p, o in learner.history if not o.success]
    again = ContextualCORL(task, [-1.0], skill, seed=0, failed=failed)
    drive(again, task.with_context([-1.0]), max_trials=60)
    for p, _ in again.history:
        assert all(np.linalg.norm(p.w - f) >= 1e-5 for f in failed)


def test_a_task_without_contexts_runs_as_before():
    """The plain synthetic task: no context anywhere, the same trials as Algorithm 1 gave before."""
    from corl.methods import make_method
    from corl.session import StoredRun

    task = SyntheticTask((0.2, 1.1))
    run = StoredRun.new(task, task_spec="synthetic", method="CORL+PIBU", seed=0)
    assert "context" not in run._record["config"] and "contextual" not in run._record["config"]
    a, b = make_method("CORL+PIBU", task, seed=0), make_method("CORL+PIBU", SyntheticTask((0.2, 1.1)), seed=0)
    a.run(max_trials=200)
    b.run(max_trials=200)
    assert [(p.index, p.step, p.theta.tolist()) for p, _ in a.history] == [
        (p.index, p.step, p.theta.tolist()) for p, _ in b.history]
    with pytest.raises(InputError, match="has no contexts"):
        plain_learner(task)
    with pytest.raises(InputError, match="has no contexts"):
        StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, context=[0.1])
