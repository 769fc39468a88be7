"""The scene's own g_S governs where the joint models would propose (corl.contexts.guard)."""

import numpy as np
import pytest

import corl.contexts.learn as learn
from corl.acquisition.guarded import Guarded
from corl.contexts import ContextualCORL, Skill
from corl.contexts.guard import SceneGuard
from corl.experiments.contexts import train
from corl.loop import drive
from corl.methods import settings_for
from corl.optimizers.safe import SafeBOOptimizer
from corl.problem import Bounds, Outcome
from corl.tasks.registry import load_task

UNIT2 = Bounds(np.zeros(2), np.ones(2))


def _rollout(x):  # the optimum (0.3, 0.7); a failure above x2 = 0.8
    return Outcome(False, None) if x[1] > 0.8 else Outcome(True, -float(np.sum((x - [0.3, 0.7]) ** 2)))


class _Acquisition:
    def __call__(self, X):
        return np.sum(np.asarray(X), axis=1)

    def boundary_level(self, X):
        return np.zeros(len(X))


def test_guarded_is_minus_inf_where_not_allowed_and_the_acquisition_elsewhere():
    g = Guarded(_Acquisition(), lambda X: np.asarray(X)[:, 0] < 0.5)
    X = np.array([[0.1, 0.2], [0.7, 0.1]])
    np.testing.assert_array_equal(g(X), [0.30000000000000004, -np.inf])
    np.testing.assert_array_equal(g.on_lattice(X, None), g(X))  # the acquisition has no lattice: called on it
    assert callable(g.boundary_level) and np.all(g.boundary_level(X) == 0)


def test_a_guarded_optimizer_proposes_only_where_the_guard_allows():
    """The optimum (0.3, 0.7) lies where the guard forbids (x1 > 0.5 only): every proposal stays allowed."""

    class Half:
        def allowed(self, X, s):
            return lambda P: np.asarray(P)[:, 0] > 0.5

    rollout = _rollout
    opt = SafeBOOptimizer(UNIT2, max_evals=25, seed=0)
    opt.guard = Half()
    start = np.array([0.6, 0.2])
    opt.tell(start, rollout(start))
    asked = []
    while not opt.done and len(asked) < 20:
        x = opt.ask()
        asked.append(x)
        opt.tell(x, rollout(x))
    assert len(asked) >= 3
    assert all(x[0] > 0.5 for x in asked), asked


def test_scene_guard_allows_near_a_success_and_not_beside_a_failure():
    task = load_task("synthetic-context", seed=0)
    s = settings_for(task)
    guard = SceneGuard(task.theta_bounds, s.regression, s.classifier, s.optimizer_settings().seib.p_band,
                       earlier=(np.array([[1.0]]), np.array([False])))  # an earlier start failed at theta 1
    allowed = guard.allowed(np.array([[0.0]]), np.array([True]))
    ok = allowed(np.array([[0.0], [0.05], [1.0], [2.5]]))
    assert ok[0] and ok[1] and not ok[2] and not ok[3]


@pytest.fixture(scope="module")
def skill(tmp_path_factory):
    task = load_task("synthetic-context", seed=0)
    store = tmp_path_factory.mktemp("guard") / "train.corl"
    train("synthetic-context", 0, np.array([[0.0], [0.8], [-0.7]]), store)
    return task, Skill.load(store, task)


def test_every_proposal_in_a_new_scene_is_one_the_scene_own_g_s_allows(skill, monkeypatch):
    task, sk = skill
    checked = []

    class Recording(SceneGuard):
        def allowed(self, X, s):
            inner = super().allowed(X, s)
            checked.append(inner)
            return inner

    monkeypatch.setattr(learn, "SceneGuard", Recording)
    learner = ContextualCORL(task, [0.4], sk, seed=0)
    scene = task.with_context([0.4])
    drive(learner, scene, max_trials=60)
    assert checked, "the black-box step ran without the scene's guard"
    for opt in learner.optimizers:
        assert isinstance(opt.guard, Recording)
        # each black-box trial: where the scene's own g_S, on the data before it, allowed a trial
        own = [i for i in range(len(opt.X_)) if i >= 1]
        for i in own:
            before = opt.guard.allowed(opt.X_[:i], opt.success_[:i])
            assert before(opt.X_[i:i + 1])[0], (i, opt.X_[i])


def test_only_a_scene_learned_beside_others_is_guarded(skill):
    """The first scene's joint models hold its own data only: nothing to guard against."""
    task, sk = skill
    s = settings_for(task)
    alone = learn.contextual_factory(task, s, sk.data.__class__.empty(1, 1), [0.0])
    beside = learn.contextual_factory(task, s, sk.data, [0.4], refine=True)
    rng = np.random.default_rng(0)
    assert alone(task.theta_bounds, np.zeros(1), rng).guard is None
    assert isinstance(beside(task.theta_bounds, np.zeros(1), rng).guard, SceneGuard)
