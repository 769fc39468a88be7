"""What a store teaches across scenes: per-theta outcomes, exactly what a run learned from, the
failed motions of a scene, and a with_context that is checked before anything runs."""

import numpy as np
import pytest

from corl.contexts import ContextualCORL, Skill, failed_motions, learned, snapshot
from corl.contexts.skill import scene_of
from corl.errors import InputError
from corl.session import StoredRun
from corl.store import RunStore
from corl.tasks.synthetic import ContextualSyntheticTask


class PathFails(ContextualSyntheticTask):
    """Succeeds by theta as the synthetic family, except motions of radius 0.80-0.85: a step-1 path
    at theta0 fails although theta0 itself is safe (success depends on the path, Sec. VI-A)."""

    def rollout(self, w):
        out = super().rollout(w)
        if 0.80 < np.hypot(*w) < 0.85:
            from corl.problem import Outcome

            return Outcome(False, None, {"path": True})
        return out

    def with_context(self, c):
        return PathFails(self.w0, critical_distance=self.critical_distance, context=c)


def _run(store, task, c, **kw):
    with RunStore(store, create=True) as db:
        pass
    with RunStore(store, create=False, readonly=True) as ro:
        run = StoredRun.new(task, task_spec="x", method="CORL", seed=0, context=[c], learned_from=ro, **kw)
    with RunStore(store) as db:
        run.attach(db)
        run.run(scene_of(task, [c]) if c != float(task.context[0]) else task, max_trials=400)
    return run


def test_a_failed_path_at_a_safe_theta_does_not_mark_that_theta_failed(tmp_path):
    task = PathFails((0.5, 0.5))
    store = tmp_path / "s.corl"
    run = _run(store, task, 0.0)
    fails = [(p.step, p.theta.tolist()) for p, o in run.history if not o.success]
    assert any(step == "optimization" for step, _ in fails)  # a step-1 path at theta0 failed
    data, anchors = learned(store, task)
    theta0 = np.array([np.arctan2(0.5, 0.5)])
    row = [i for i, t in enumerate(data.theta) if np.allclose(t, theta0)]
    assert row and data.success[row[0]] and np.isfinite(data.returns[row[0]])
    assert len(failed_motions(store, task, [0.0])) == len(fails)
    assert failed_motions(store, task, [0.5]) == []


def test_a_run_in_a_context_reopens_exactly_however_the_store_grew(tmp_path):
    task = ContextualSyntheticTask((0.5, 0.5))
    store = tmp_path / "s.corl"
    _run(store, task, 0.0)
    second = _run(store, task, 0.6)
    with RunStore(store, readonly=True, create=False) as ro:
        info = ro.latest_run()
        assert info.config["learned_from"] == {"1": ro.run(1).n_told}
        assert snapshot(ro, task) == {"1": ro.run(1).n_told, "2": info.n_told}
    _run(store, task, -0.6)  # a third scene: reopening the second must not see it
    with RunStore(store, readonly=True, create=False) as ro:
        again = StoredRun.open(ro, task, 2)
    assert [(p.index, p.theta.tolist()) for p, _ in again.history] == [
        (p.index, p.theta.tolist()) for p, _ in second.history]


class Broken(ContextualSyntheticTask):
    def __init__(self, how, **kw):
        super().__init__(**kw)
        self.how = how

    def with_context(self, c):
        if self.how == "self":
            return self
        if self.how == "raises":
            raise RuntimeError("no scene")
        if self.how == "none":
            return None
        if self.how == "box":
            other = ContextualSyntheticTask(context=c)
            other.theta_bounds = type(self.theta_bounds)(np.array([-1.0]), np.array([1.0]))
            return other
        return ContextualSyntheticTask(context=-np.asarray(c))


@pytest.mark.parametrize("how, says", [("self", "context"), ("negated", "context"), ("raises", "raised RuntimeError"),
                                       ("none", "returned None"), ("box", "theta_bounds")])
def test_with_context_is_checked_before_anything_runs(how, says):
    task = Broken(how)
    with pytest.raises(InputError, match=says) as err:
        scene_of(task, [0.3])
    assert "\n" not in str(err.value)


def test_a_scene_with_no_start_is_refused_before_any_trial():
    """The skill's motion cannot realise its theta and the scene has no demonstration: one line."""
    from corl.contexts import Anchor, ContextData

    class Unreachable(ContextualSyntheticTask):
        def with_context(self, c):
            return Unreachable((0.5, 0.5), context=c)

        def constraint(self, w, theta):  # for c > 0.5 no w satisfies h: |w|^2 + 1 = 0
            h, J = super().constraint(w, theta)
            if float(self.context[0]) <= 0.5:
                return h, J
            return np.array([h[0], w @ w + 1.0]), np.vstack([J, 2.0 * w[None]])

        def demonstration(self):
            if float(self.context[0]) > 0.5:
                raise InputError("no demonstration in this scene")
            return super().demonstration()

    task = Unreachable((0.5, 0.5))
    data = ContextData.empty(1, 1).add([0.0], [0.0], True, 1.0)
    skill = Skill(task, data, [Anchor(np.zeros(1), np.array([1.0, 0.0]), np.zeros(1), 1.0)])
    with pytest.raises(InputError, match="out of the skill's reach"):
        skill.policy([0.9])  # never a w that does not realise its theta
    with pytest.raises(InputError, match="no start can be realised"):
        ContextualCORL(task, [0.9], skill)
