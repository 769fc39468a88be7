"""The task protocol, whole (issue 12, item 3): members checked before any rollout, optional members
declared in corl.problem, the factory's seed, --rollout-every-step, ask without reference()."""

from __future__ import annotations

import json
import textwrap
import uuid

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError
from corl.problem import Outcome
from corl.problem import DEPRECATED_MEMBERS, OPTIONAL_MEMBERS, REQUIRED_MEMBERS, check_reference
from corl.tasks.registry import load_task

# A user's task module: a linear 1-D task whose theta is w[0], with variants that break the protocol.
MODULE = '''
import numpy as np
from corl.problem import Bounds, Demonstration, Outcome

ROLLOUTS = []


class Line:
    name = "line"
    theta_bounds = Bounds(np.array([-1.0]), np.array([1.0]))
    w_bounds = None

    def __init__(self, seed=0, offset=0.0):
        self.seed, self.offset = seed, offset

    def demonstration(self):
        return Demonstration(np.array([0.0, 1.0]), np.array([self.offset]))

    def cost_residuals(self, w):
        return np.array([w[1]]), np.array([[0.0, 1.0]])

    def constraint(self, w, theta):
        return np.array([w[0] - theta[0]]), np.array([[1.0, 0.0]])

    def theta_of(self, w):
        return np.array([w[0]])

    def rollout(self, w):
        ROLLOUTS.append(w)
        return Outcome(True, float(-w[0] ** 2))

    def simulate(self, w):  # a method that happens to be called simulate: corl must not call it
        raise RuntimeError("simulate is the task's own business")


class WithReference(Line):
    joint_names = ("a", "b")

    def reference(self, w, rate):
        t = np.arange(3) / rate
        return t, np.tile(w, (3, 1))


class BadReference(Line):
    def reference(self, w, rate):
        return np.arange(3) / rate, w  # (n,) instead of (K, Q)


def make_task(seed=0):
    return Line(seed)


def make_task_no_seed():
    return Line(7)


def make_task_off():
    return Line(offset=0.3)  # w0 realises theta = 0, not 0.3


def make_task_raises():
    raise FileNotFoundError("robot.xml")


def make_task_missing():
    task = Line()
    task.rollout = None
    return type("Half", (), {"name": "half", "theta_bounds": task.theta_bounds, "w_bounds": None,
                             "demonstration": task.demonstration, "cost_residuals": task.cost_residuals,
                             "constraint": task.constraint, "theta_of": task.theta_of})()


def make_with_reference():
    return WithReference()


def make_bad_reference():
    return BadReference()
'''


@pytest.fixture
def module(tmp_path, monkeypatch):
    name = f"usertask_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(MODULE))
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    return name


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def one_line_error(res, *needles):
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]


def test_the_factory_gets_the_seed_when_it_takes_one(module):
    assert load_task(f"{module}:make_task", seed=5).seed == 5
    assert load_task(f"{module}:make_task_no_seed", seed=5).seed == 7


def test_bad_tasks_are_one_line_errors_before_any_rollout(module, tmp_path):
    import importlib

    mod = importlib.import_module(module)
    out = tmp_path / "out"
    one_line_error(invoke("run", f"{module}:make_task_raises", "--out", out), "make_task_raises",
                   "raised FileNotFoundError: robot.xml")
    one_line_error(invoke("run", f"{module}:make_task_missing", "--out", out), "lacks rollout", "corl.problem.Task")
    one_line_error(invoke("run", f"{module}:make_task_off", "--out", out, "--no-video"),
                   "max|h(w0, theta0)| = 0.3", "corl.realise.project_demonstration")
    assert mod.ROLLOUTS == []


def test_an_optional_member_of_the_wrong_kind_is_named():
    from corl.problem import check_task
    from corl.tasks.synthetic import SyntheticTask

    task = SyntheticTask(np.array([1.0, 0.0]))
    task.reference = np.zeros(3)
    with pytest.raises(InputError, match="optional member 'reference' must be a method"):
        check_task(task)
    del task.reference
    task.theta_labels = ("a", "b")
    with pytest.raises(InputError, match="'theta_labels' has 2 entries, theta has 1"):
        check_task(task)


def test_the_old_name_projection_still_gives_h_with_a_warning():
    from corl.learner import CORL
    from corl.problem import check_task, constraint_of
    from corl.realise import constraint_violation
    from corl.tasks.synthetic import SyntheticTask

    new = SyntheticTask(np.array([1.0, 0.2]))
    members = {m: getattr(new, m) for m in REQUIRED_MEMBERS if m != "constraint"}
    old = type("Old", (), {**members, "projection": new.constraint})()
    with pytest.warns(FutureWarning, match="rename it to constraint"):
        assert check_task(old) is old
    with pytest.warns(FutureWarning):
        assert constraint_of(old) == new.constraint
    with pytest.warns(FutureWarning):
        violation = constraint_violation(old, [1.0, 0.5], [0.2])
    assert violation == pytest.approx(constraint_violation(new, [1.0, 0.5], [0.2]))
    assert constraint_of(new) == new.constraint  # the new name: no warning (pytest's -W error would fail here)
    with pytest.warns(FutureWarning):
        learner = CORL(old, lambda *args: None)  # checks h(w0, theta0)
        learner.ask()
        learner.tell(Outcome(True, 0.0))  # step 1 (Eq. 8) on the old name's h
    assert learner.history and np.allclose(learner.ask().theta, old.theta_of(old.demonstration().w))


def test_every_optional_member_the_code_reads_is_declared():
    import pathlib
    import re

    src = pathlib.Path(__file__).resolve().parents[1] / "src" / "corl"
    read = set()
    for path in src.rglob("*.py"):
        if "tasks" in path.parts or "mujoco" in path.parts:
            continue  # a task's own modules read their own attributes
        text = path.read_text()
        read |= set(re.findall(r"(?:getattr|hasattr)\((?:task|self\.task|the_task), \"(\w+)\"", text))
    assert read, "the pattern found nothing: the test would pass vacuously"
    undeclared = read - set(OPTIONAL_MEMBERS) - set(REQUIRED_MEMBERS) - set(DEPRECATED_MEMBERS)
    assert not undeclared, f"read by name but not declared in corl.problem: {undeclared}"


def test_a_task_method_called_simulate_is_not_called(module, tmp_path):
    res = invoke("run", f"{module}:make_task", "--out", tmp_path / "out", "--no-video", "--json", "-q")
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["success"] and "door_angle_final" not in summary
    assert summary["J_demo"] == pytest.approx(1.0) and summary["final_info"] == {}


def test_rollout_every_step_flag_is_stored_and_checked_on_resume(module, tmp_path):
    out = tmp_path / "out"
    res = invoke("run", f"{module}:make_task", "--out", out, "--no-video", "--json", "-q", "--no-rollout-every-step")
    assert res.exit_code == 0, res.output
    from corl.store import RunStore

    with RunStore(out / "run.corl", readonly=True) as db:
        info = db.latest_run()
        assert info.config["corl_overrides"] == {"rollout_every_step": False}
        assert info.config["learner"]["rollout_every_step"] is False
        steps = [t.proposal.step for t in db.trials(info.id)]
    assert steps.count("optimization") == 1  # one rollout of the converged step
    from corl.session import StoredRun

    with RunStore(out / "run.corl") as db:  # reopened (resume, corl report): the same configuration, replayed
        reopened = StoredRun.open(db, load_task(f"{module}:make_task"))
        assert reopened.learner.config.rollout_every_step is False and len(reopened.history) == len(steps)
    one_line_error(invoke("run", f"{module}:make_task", "--out", out, "--resume", "--rollout-every-step"),
                   "differs from the run being resumed")


def test_ask_refuses_a_task_without_reference_and_raw_is_labelled(module, tmp_path):
    store = tmp_path / "s.corl"
    one_line_error(invoke("ask", "--store", store, "--task", f"{module}:make_task"), "has no reference(w, rate)",
                   "--raw")
    from corl.store import RunStore

    if store.exists():
        with RunStore(store, readonly=True) as db:
            info = db.latest_run()
            assert info is None or db.trials(info.id) == []  # nothing was handed out
    res = invoke("ask", "--store", store, "--task", f"{module}:make_task", "--raw")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output.strip().splitlines()[-1])
    assert doc["raw_parameters"] is True and "raw_parameters" in doc["csv"]
    text = open(doc["csv"]).read().splitlines()
    assert text[0].startswith("# raw parameters w") and "not a joint trajectory" in text[0]
    assert text[1] == "w0,w1" and len(text) == 3


def test_ask_writes_the_reference_at_the_rate(module, tmp_path):
    res = invoke("ask", "--store", tmp_path / "s.corl", "--task", f"{module}:make_with_reference", "--rate", "50")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output.strip().splitlines()[-1])
    rows = open(doc["csv"]).read().splitlines()
    assert rows[0] == "t,a,b" and len(rows) == 4
    assert float(rows[2].split(",")[0]) == pytest.approx(0.02)


def test_a_reference_of_the_wrong_shape_is_named(module, tmp_path):
    one_line_error(invoke("ask", "--store", tmp_path / "s.corl", "--task", f"{module}:make_bad_reference"),
                   "reference(w, rate) returned t (3,) and q (2,)")


def test_check_reference_contract():
    class T:
        name = "t"
        joint_names = ("a",)

    t, q = check_reference(T(), np.arange(4) / 10.0, np.zeros((4, 1)), 10.0)
    assert q.shape == (4, 1)
    with pytest.raises(InputError, match="ignored the rate"):
        check_reference(T(), np.arange(4), np.zeros((4, 1)), 10.0)
    with pytest.raises(InputError, match="joint_names has 1"):
        check_reference(T(), np.arange(4) / 10.0, np.zeros((4, 2)), 10.0)


def test_settings_live_below_the_tasks():
    import corl.experiments.methods as methods
    import corl.settings as settings

    assert methods.MethodSettings is settings.MethodSettings
    for name in settings.__all__:
        assert getattr(settings, name) is not None
