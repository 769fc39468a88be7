"""The switch of ``examples/panda_switch.py``, built from a recorded demonstration instead of by hand.

Four things and a test of success: the scene with the Panda (``build_robot`` of the hand-written
example: robot, servos, the sprung paddle), its moving joints (the robot's own), a recording of the
demonstration as the robot logged it (``examples/data/panda_switch_demo.npz``: joint positions at the
controller's 500 Hz, made by ``examples/data/record_panda_switch.py``) and the object's name,
``"paddle"``. :func:`corl.mujoco.task_from_recording` replays the recording, finds that the fingertips
touch the paddle from 1.19 s to the end, and derives the rest:

* theta (1,) : where the fingertips press, along the paddle's ``-x`` axis (from the hinge), m; bounds
               from the paddle's geometry (0 .. 0.16 m)
* h(w, theta): every 0.1 s from 0.4 s before the touch, the fingertips' contact point where the
               recording had it relative to the (turning) paddle, shifted to theta; the hand held
               square to the paddle as recorded; the gripper as recorded; the start as recorded
* J(w)       : squared joint accelerations; w0 the B-spline fitted to the recording, projected
* S, R       : below, the only task code here: read from the rollout's log (the paddle's angle,
               the contact force, where the contact point is on the paddle)

Run it:  corl run examples.panda_switch_demo:make_task --seed 0
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from corl.mujoco import task_from_recording
from examples.panda_switch import F_REF, LENGTH, SWITCH, THICK, TIP_HALF, build_robot

RECORDING = Path(__file__).with_name("data") / "panda_switch_demo.npz"


def success(log) -> bool:
    """The switch flipped, the fingertips stayed whole on the paddle's top and touched 80 % of the time."""
    touch = log["touch"]
    if not touch.any():
        return False
    after = slice(int(np.argmax(touch)), None)
    along, gap = -log["point"][after, 0], log["point"][after, 2] - THICK / 2  # m from the hinge, above the top
    on_paddle = np.all((along > TIP_HALF) & (along < LENGTH - TIP_HALF) & (np.abs(gap) < 0.02))
    return bool(log["object_q"][:, 0].max() > SWITCH and on_paddle and touch[after].mean() > 0.8)


def return_(log) -> float:
    """``1 - F / F_REF``, F the mean contact force from the first touch on (N)."""
    return 1.0 - float(log["force"][int(np.argmax(log["touch"])):].mean()) / F_REF


def method_settings():
    """As the hand-written task's: GP length scales in metres of theta, the trust region in radians of w."""
    from corl.settings import ClassifierConfig, CORLConfig, MethodSettings, RegressionConfig

    return MethodSettings(regression=RegressionConfig(lengthscale=0.04, signal_std=0.5, noise_std=0.01),
                          classifier=ClassifierConfig(lengthscale=0.02, signal_std=10.0, prior_mean=-7.0),
                          corl=CORLConfig(eps_max=0.3, eps_w=1e-4, max_rounds=4, max_optimization_steps=12,
                                          max_rl_trials=25))


def make_task():
    """The switch task derived from the recording."""
    return task_from_recording(build_robot(), None, RECORDING, "paddle", return_=return_, success=success,
                               name="panda_switch_demo", directions=("-x",), hold_orientation=True,
                               settings=method_settings())


if __name__ == "__main__":
    task = make_task()
    iv = task.contacts.intervals[0]
    print(f"contact {iv.start:.2f}-{iv.end:.2f} s with {', '.join(iv.geoms)}; theta0 = {task.theta0}")
    demo = task.demonstration()
    print(task.demo_report)
    print("demonstration:", task.rollout(demo.w))
