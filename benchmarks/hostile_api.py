"""Bad input to corl's public Python API (issues 21, 22): settings, the optimizer API, contexts, the MuJoCo kit's loaders.

Each case calls one public function in this process, as a user's script would. A case either must
be *refused* (a :class:`corl.errors.CorlError` with a one-line message) or must *work* (no
exception at all: a huge but finite return is data, not an error). The table shows per case what
happened and the first line of the message; the last line counts raw exceptions (anything that is
not a CorlError), multi-line messages, and refusals or acceptances where the other was due. Every
count must read 0.

    PYTHONPATH=src python benchmarks/hostile_api.py
    PYTHONPATH=src python benchmarks/hostile.py        # the CLI cases, then these
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path
from typing import Callable

import numpy as np

REFUSE, WORK = "refused", "works"


def _settings_cases() -> list[tuple[str, str, Callable]]:
    from corl.learner import CORLConfig
    from corl.problem import Bounds
    from corl.optimizers.registry import OptimizerSettings
    from corl.settings import ClassifierConfig, MethodSettings, RegressionConfig, SEIBConfig, SolverConfig

    return [
        ("RegressionConfig(lengthscale='wide', ...)", REFUSE,
         lambda: RegressionConfig(lengthscale="wide", signal_std=1.0, noise_std=0.1)),
        ("RegressionConfig(lengthscale=0.2) alone", REFUSE, lambda: RegressionConfig(lengthscale=0.2)),
        ("RegressionConfig(noise_std=nan, ...)", REFUSE,
         lambda: RegressionConfig(lengthscale=0.1, signal_std=1.0, noise_std=math.nan)),
        ("ClassifierConfig(lengthscale=(0.1, -1), ...)", REFUSE,
         lambda: ClassifierConfig(lengthscale=(0.1, -1.0), signal_std=1.0)),
        ("CORLConfig(max_rl_trials='10')", REFUSE, lambda: CORLConfig(max_rl_trials="10")),
        ("CORLConfig(max_rl_trials=nan)", REFUSE, lambda: CORLConfig(max_rl_trials=math.nan)),
        ("CORLConfig(max_rl_trials=2.5)", REFUSE, lambda: CORLConfig(max_rl_trials=2.5)),
        ("CORLConfig(eps_max=nan)", REFUSE, lambda: CORLConfig(eps_max=math.nan)),
        ("CORLConfig(rl_budget=40)", REFUSE, lambda: CORLConfig(rl_budget=40)),
        ("MethodSettings(rl_budget=40)", REFUSE, lambda: MethodSettings(rl_budget=40)),
        ("MethodSettings(failure_return='bad')", REFUSE, lambda: MethodSettings(failure_return="bad")),
        ("MethodSettings(ucb_kappa=nan)", REFUSE, lambda: MethodSettings(ucb_kappa=math.nan)),
        ("MethodSettings(cma_sigma0=-0.1)", REFUSE, lambda: MethodSettings(cma_sigma0=-0.1)),
        ("MethodSettings(theta_scale=(1, -2))", REFUSE, lambda: MethodSettings(theta_scale=(1.0, -2.0))),
        ("MethodSettings(corl={...})", REFUSE, lambda: MethodSettings(corl={"eps_max": 0.1})),
        ("SEIBConfig(far_beta=inf)", REFUSE, lambda: SEIBConfig(far_beta=math.inf)),
        ("SolverConfig(tol_steps=1)", REFUSE, lambda: SolverConfig(tol_steps=1.0)),
        ("Bounds([], [])", REFUSE, lambda: Bounds(np.array([]), np.array([]))),
        ("MethodSettings(corl=CORLConfig(eps_max=.1))", WORK, lambda: MethodSettings(corl=CORLConfig(eps_max=0.1))),
        ("OptimizerSettings(ucb_kappa=nan)", REFUSE, lambda: OptimizerSettings(ucb_kappa=math.nan)),
        ("OptimizerSettings(failure_return='x')", REFUSE, lambda: OptimizerSettings(failure_return="x")),
        ("OptimizerSettings(stop_distance='0.1')", REFUSE, lambda: OptimizerSettings(stop_distance="0.1")),
        ("OptimizerSettings(cma_sigma0=inf)", REFUSE, lambda: OptimizerSettings(cma_sigma0=math.inf)),
    ]


def _two_tells():
    import corl

    opt = corl.make_optimizer("CORL", ([0.0, 0.0], [1.0, 1.0]), [0.5, 0.5], budget=10, seed=0)
    x = opt.ask()
    opt.tell(x, (True, 1.0))
    opt.tell(x, (True, 1.0))


def _huge_returns():
    import corl

    opt = corl.make_optimizer("CORL", ([0.0, 0.0], [1.0, 1.0]), [0.5, 0.5], budget=10, seed=0)
    for r in (1e154, 1e300, -1e300, 3.0):
        opt.tell(opt.ask(), (True, r))
    opt.ask()


def _learner_two_tells():
    from corl.methods import make_method
    from corl.tasks.synthetic import SyntheticTask

    task = SyntheticTask((0.6, 0.4))
    learner = make_method("CORL", task, seed=0)
    p = learner.ask()
    learner.tell(task.rollout(p.w))
    learner.tell(task.rollout(p.w))


def _optimizer_cases() -> list[tuple[str, str, Callable]]:
    import corl
    from corl.methods import make_method
    from corl.tasks.synthetic import SyntheticTask

    box, start = ([0.0, 0.0], [1.0, 1.0]), [0.5, 0.5]
    return [
        ("make_optimizer(seed=-1)", REFUSE, lambda: corl.make_optimizer("CORL", box, start, seed=-1)),
        ("make_optimizer(seed='abc')", REFUSE, lambda: corl.make_optimizer("CORL", box, start, seed="abc")),
        ("make_optimizer(seed=1.5)", REFUSE, lambda: corl.make_optimizer("CORL", box, start, seed=1.5)),
        ("make_optimizer(start='x')", REFUSE, lambda: corl.make_optimizer("CORL", box, "x")),
        ("make_optimizer(settings={})", REFUSE, lambda: corl.make_optimizer("CORL", box, start, settings={})),
        ("opt.tell('abc', ...)", REFUSE, lambda: corl.make_optimizer("UCB", box, start).tell("abc", (True, 1.0))),
        ("opt.tell twice without ask", REFUSE, _two_tells),
        ("CORL learner: tell twice without ask", REFUSE, _learner_two_tells),
        ("make_method(None, task)", REFUSE, lambda: make_method(None, SyntheticTask())),
        ("make_method(settings={})", REFUSE, lambda: make_method("CORL", SyntheticTask(), settings={})),
        ("make_method('CORL', None)", REFUSE, lambda: make_method("CORL", None)),
        ("opt.tell(x) without an outcome", REFUSE, lambda: corl.make_optimizer("UCB", box, start).tell(None)),
        ("optimize(callback=3)", REFUSE, lambda: corl.optimize(lambda x: (True, 1.0), box, start, callback=3)),
        ("register_optimizer('CORL')", REFUSE, lambda: corl.register_optimizer("CORL")),
        ("returns 1e154, 1e300, -1e300, then ask", WORK, _huge_returns),
        ("optimize(f -> 1e200)", WORK,
         lambda: corl.optimize(lambda x: (True, 1e200 * float(x[0])), box, start, budget=6, seed=0)),
    ]


MJCF_ARM = """<mujoco><worldbody><body name="l1"><joint name="j1" type="hinge"/><geom size=".05"/>
<site name="tip"/></body></worldbody></mujoco>"""


def _kit_cases(folder: Path) -> list[tuple[str, str, Callable]]:
    from corl.mujoco import Robot, add_force_sensor, add_servos, example_robot_dir, load_spec

    missing_include = folder / "scene.xml"
    missing_include.write_text('<mujoco><include file="nowhere.xml"/></mujoco>')

    def robot():
        return Robot.from_spec(load_spec(MJCF_ARM), ["j1"])

    return [
        ("load_spec(malformed MJCF)", REFUSE, lambda: load_spec("<mujoco><worldbody><body></mujoco>")),
        ("load_spec(malformed URDF)", REFUSE, lambda: load_spec('<robot name="r"><link name="a"></robot>')),
        ("load_spec(missing include)", REFUSE, lambda: load_spec(str(missing_include))),
        ("load_spec(duplicate names)", REFUSE, lambda: load_spec(
            '<mujoco><worldbody><body name="a"><geom size=".1"/></body><body name="a"><geom size=".1"/></body>'
            "</worldbody></mujoco>")),
        ("add_servos(unknown joint)", REFUSE, lambda: add_servos(load_spec(MJCF_ARM), ["nope"], [1.0], [1.0], [1.0])),
        ("add_force_sensor(unknown site)", REFUSE, lambda: add_force_sensor(load_spec(MJCF_ARM), "nope")),
        ("Robot.check_q([nan])", REFUSE, lambda: robot().check_q([math.nan])),
        ("example_robot_dir('../../../../..')", REFUSE, lambda: example_robot_dir("../../../../..")),
    ]


def _context_cases() -> list[tuple[str, str, Callable]]:
    """Contexts (issue 22): a skill, a contextual learner and the task protocol, given bad scenes."""
    from corl.contexts import Anchor, ContextData, ContextualCORL, ContextualModels, Skill
    from corl.problem import Bounds, check_task
    from corl.tasks.synthetic import ContextualSyntheticTask, SyntheticTask

    task = ContextualSyntheticTask((0.5, 0.5))
    data = ContextData.empty(1, 1).add([0.0], [0.0], True, 1.0)
    anchor = Anchor(np.zeros(1), np.array([1.0, 0.0]), np.zeros(1), 1.0)

    def skill():
        return Skill(task, data, [anchor])

    class HalfContexts(SyntheticTask):
        context_bounds = Bounds(np.array([0.0]), np.array([1.0]))  # no context, no with_context

    return [
        ("Skill.policy(c outside the box)", REFUSE, lambda: skill().policy([3.0])),
        ("Skill.policy([nan])", REFUSE, lambda: skill().policy([math.nan])),
        ("Skill.policy('near the door')", REFUSE, lambda: skill().policy("near the door")),
        ("Skill.policy(two numbers for one context)", REFUSE, lambda: skill().policy([0.1, 0.2])),
        ("Skill(..., anchors=[])", REFUSE, lambda: Skill(task, data, [])),
        ("Skill(..., p_min=1.5)", REFUSE, lambda: Skill(task, data, [anchor], p_min=1.5)),
        ("Skill(task without contexts, ...)", REFUSE, lambda: Skill(SyntheticTask(), data, [anchor])),
        ("ContextualCORL(c = inf)", REFUSE, lambda: ContextualCORL(task, [math.inf], skill())),
        ("task.with_context([2.0])", REFUSE, lambda: task.with_context([2.0])),
        ("ContextData(success without return)", REFUSE,
         lambda: ContextData(np.zeros((1, 1)), np.zeros((1, 1)), [True], [math.nan])),
        ("ContextualModels(prior of another shape)", REFUSE,
         lambda: ContextualModels(task.theta_bounds, task.context_bounds, ContextData.empty(2, 1), [0.0])),
        ("check_task(context_bounds only)", REFUSE, lambda: check_task(HalfContexts())),
        ("Skill.policy(c at the box's corner)", WORK, lambda: skill().policy([1.0])),
    ]


def run_case(expect: str, fn: Callable) -> tuple[str, str, bool]:
    """(what happened, first line of the message, counts as a problem)."""
    from corl.errors import CorlError

    try:
        fn()
    except CorlError as e:
        message = str(e)
        problem = expect != REFUSE or "\n" in message.strip()
        return (REFUSE if "\n" not in message.strip() else "refused (multi-line)"), message.splitlines()[0], problem
    except Exception as e:  # noqa: BLE001 - a raw exception is what this benchmark counts
        return f"RAW {type(e).__name__}", str(e).splitlines()[0] if str(e) else "", True
    return WORK, "", expect != WORK


def main() -> int:
    try:
        import mujoco  # noqa: F401

        have_mujoco = True
    except ImportError:
        have_mujoco = False
    rows, problems = [], 0
    with tempfile.TemporaryDirectory() as tmp:
        groups = [("settings", _settings_cases()), ("optimizer API", _optimizer_cases()),
                  ("contexts", _context_cases())]
        if have_mujoco:
            groups.append(("kit loaders", _kit_cases(Path(tmp))))
        for group, cases in groups:
            for name, expect, fn in cases:
                got, message, problem = run_case(expect, fn)
                problems += problem
                rows.append((group, name, expect, got, message[:90], "PROBLEM" if problem else ""))
    width = max(len(r[1]) for r in rows)
    print(f"{'group':14} {'case':{width}} {'expected':9} {'got':22} first line")
    for group, name, expect, got, message, flag in rows:
        print(f"{group:14} {name:{width}} {expect:9} {got:22} {message} {flag}")
    raw = sum(r[3].startswith("RAW") for r in rows)
    print(f"{len(rows)} API cases: {raw} raw exceptions, {problems} problems (raw, multi-line, or refused/accepted wrongly)")
    return 1 if problems else 0


if __name__ == "__main__":
    raise SystemExit(main())
