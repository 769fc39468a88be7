"""The PR2 door of :mod:`corl.tasks.door`, built from a recording of its demonstration (issue 35).

Beside ``corl run door``: the same scene, demonstration and test of success, with h, theta, theta_of,
J and w0 derived from the recording instead of written by hand. (Here and not in ``examples/``: it
reuses the built-in door's scene and trial, which are not corl's public API.)

Four things and the door's own test of success: the door scene with the PR2 (``load_scene()``: the
arm's servos, the sprung handle, the latched door), its moving joints (the robot's own), a recording
of the demonstration as the robot logged it (``examples/data/door_demo.npz``: the 7 arm joints'
positions and the gripper's command at the controller's 500 Hz, made by
``examples/data/record_door.py``) and the object's name, ``"handle"``, which the gripper grasps.
:func:`corl.mujoco.find_contacts` replays the recording with the handle held (``grasp=True``:
it follows the grasped point, a position log carries no grip force), finds that the fingertip pads
pinch the bar from 1.61 s to the end, 34 mm from the pivot, and :class:`corl.mujoco.RecordedTask`
(what :func:`~corl.mujoco.task_from_recording` returns; subclassed here for the door's own trial)
derives the rest:

* theta (2,) : where the pads grasp, along the bar (the handle's ``-y`` axis, from the pivot), m,
               bounds from the handle's geometry; and the gripper's command while it holds (m,
               ``grip_bounds``: the door's own 8-28 mm), as the door's theta
* h(w, theta): every 0.1 s from 0.4 s before the grasp, the pads' midpoint where the recording had it
               relative to the turning handle and door, moved to theta; the hand's orientation
               relative to the handle as recorded; the gripper's command as recorded (theta's
               width once closed); the start
* J(w)       : squared joint accelerations; w0 the B-spline fitted to the recording, projected
* S, R       : the door's own: its simulation (latch, wrist force sensor), ``RolloutResult.success``
               (door past 0.3 rad, handle held) and ``return_of_force`` (``1 - F / 15 N``)

Run it (from the repository root):  corl run benchmarks.door_from_recording:make_task --seed 0
"""

from __future__ import annotations

from pathlib import Path

from corl.mujoco import RecordedTask, find_contacts, load_recording
from corl.tasks.door.scene import load_scene
from corl.tasks.door.sim import rollout
from corl.tasks.door.task import grasp_instant, return_of_force

RECORDING = Path(__file__).resolve().parents[1] / "examples" / "data" / "door_demo.npz"
GRIP = (0.008, 0.028)  # m, the gripper's command while it holds: the door task's width bounds


class DoorFromRecording(RecordedTask):
    """The derived task with the door's own trial: its latch opens once the handle is pressed."""

    rollout_in_worker = True  # a simulator: `corl run` rolls out in a forked process

    def run(self, w):
        """The door's :func:`corl.tasks.door.sim.rollout` of ``w``'s reference (its ``RolloutResult``)."""
        t, q = self.reference(w)
        return rollout(q, duration=self.duration, t_contact=grasp_instant(t, q), scene=load_scene())


def success(result) -> bool:
    """The door's S: opened past 0.3 rad with the handle held from the grasp on."""
    return result.success


def return_(result) -> float:
    """The door's R: ``1 - F / 15 N``, F the mean wrist force from the grasp on."""
    return return_of_force(result.force_mean)


def method_settings():
    """The door's hyperparameters (``DoorTask.method_settings``): the width's length scale is the
    paper's times the ratio of the width's range (20 mm) to the grasp's (152 mm here)."""
    from dataclasses import replace

    from corl.settings import DOOR_CLASSIFIER, DOOR_REGRESSION, CORLConfig, MethodSettings

    ratio = (GRIP[1] - GRIP[0]) / 0.152
    scales = lambda config: replace(config, lengthscale=(config.lengthscale, config.lengthscale * ratio))  # noqa: E731
    return MethodSettings(regression=scales(DOOR_REGRESSION), classifier=scales(DOOR_CLASSIFIER),
                          direct_budget=150, theta_scale=(1.0, ratio),
                          corl=CORLConfig(eps_max=0.1, eps_w=1e-5, eps_theta=0.003, max_rounds=6,
                                          max_optimization_steps=60, max_rl_trials=60, max_phase_steps=20))


def make_task():
    """The door task derived from the recording."""
    robot = load_scene().robot
    contacts = find_contacts(robot, load_recording(RECORDING), "handle", grasp=True)
    return DoorFromRecording(robot, contacts, return_, success, name="door_from_recording", directions=("-y",),
                             hold_orientation=True, grip_bounds=GRIP, settings=method_settings())


if __name__ == "__main__":
    task = make_task()
    iv = task.contacts.intervals[0]
    print(f"contact {iv.start:.2f}-{iv.end:.2f} s with {', '.join(iv.geoms)}; theta0 = {task.theta0}")
    demo = task.demonstration()
    print(task.demo_report)
    print("demonstration:", task.rollout(demo.w))
