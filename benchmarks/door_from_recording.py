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

``python benchmarks/door_from_recording.py --sweep`` learns it once per h (every 0.1 s, and the
fewest instants within ``tolerance`` of the path, :class:`RecordedTask`'s option) beside the
hand-written door, and prints trials, failures, the learner's best return, J before and after, and
one scale for both tasks' motions: the integral of the arm's squared joint accelerations (rad^2/s^3).
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


def method_settings(min_J_decrease: float = 1e-3):
    """The door's hyperparameters (``DoorTask.method_settings``): the width's length scale is the
    paper's times the ratio of the width's range (20 mm) to the grasp's (152 mm here). Beyond the
    door's: step 1 and the phase steps roll out only steps that lower J by at least 0.1 %
    (``min_J_decrease``): this h lets tiny J steps move the return by 0.14 (see the guide)."""
    from dataclasses import replace

    from corl.settings import DOOR_CLASSIFIER, DOOR_REGRESSION, CORLConfig, MethodSettings

    ratio = (GRIP[1] - GRIP[0]) / 0.152
    scales = lambda config: replace(config, lengthscale=(config.lengthscale, config.lengthscale * ratio))  # noqa: E731
    return MethodSettings(regression=scales(DOOR_REGRESSION), classifier=scales(DOOR_CLASSIFIER),
                          direct_budget=150, theta_scale=(1.0, ratio),
                          corl=CORLConfig(eps_max=0.1, eps_w=1e-5, eps_theta=0.003, max_rounds=6,
                                          max_optimization_steps=60, max_rl_trials=60, max_phase_steps=20,
                                          min_J_decrease=min_J_decrease))


def make_task(*, spacing: float = 0.1, tolerance: float | None = None, min_J_decrease: float = 1e-3):
    """The door task derived from the recording (h's instants: see :class:`RecordedTask`)."""
    robot = load_scene().robot
    contacts = find_contacts(robot, load_recording(RECORDING), "handle", grasp=True)
    options = {"name": "door_from_recording", "directions": ("-y",), "hold_orientation": True,
               "grip_bounds": GRIP, "settings": method_settings(min_J_decrease), "spacing": spacing, "tolerance": tolerance}
    return DoorFromRecording(robot, contacts, return_, success, **options)


def acceleration_integral(task, w, arm: int = 7, points: int = 2000) -> float:
    """The integral over the motion of the arm's squared joint accelerations (rad^2/s^3), by
    finite differences of ``task.spline``'s positions: one scale for motions of different splines."""
    import numpy as np

    t = np.linspace(0.0, task.duration, points)
    q = task.spline.positions(w, t)[:, :arm]
    a = np.gradient(np.gradient(q, t, axis=0), t, axis=0)
    return float(np.sum(a ** 2) * (t[1] - t[0]))


def sweep() -> None:
    """Learn the door once per h and print one line each (CORL, seed 0; the door's runs do not
    depend on the seed)."""
    import tempfile
    import time

    from corl.learner import cost_of
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.door.task import DoorTask
    from corl.versions import library_versions

    cases = [("hand-written door (corl run door)", lambda: DoorTask(seed=0)),
             ("derived, every 0.1 s (default)", make_task)]
    cases += [(f"derived, min_J_decrease {f:g}", lambda f=f: make_task(min_J_decrease=f)) for f in (0.0, 1e-4, 1e-2)]
    cases += [(f"derived, spacing {sp:g} s, tolerance {tol * 1e3:g} mm",
               lambda sp=sp, tol=tol: make_task(spacing=sp, tolerance=tol))
              for sp in (0.1, 0.05) for tol in (0.0005, 0.001, 0.002)]
    print(", ".join(f"{k} {v}" for k, v in library_versions().items()))
    print(f"{'h':45s} {'pins':>4s} {'trials':>6s} {'fail':>4s} {'return':>7s} {'J demo':>7s} {'J best':>7s}"
          f" {'ratio':>5s} {'acc demo':>8s} {'acc best':>8s} {'s':>5s}")
    for label, build in cases:
        task = build()
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as folder, RunStore(Path(folder) / "run.corl") as db:
            run = StoredRun.start(db, task, task_spec="benchmarks.door_from_recording:make_task", method="CORL", seed=0)
            run.run(task)
        w0, best = run.history[0][0].w, run.best
        pins = "13" if not hasattr(task, "times") else str(sum(len(t) for t in task.times))
        J0 = cost_of(task, w0)
        print(f"{label:45s} {pins:>4s} {len(run.history):6d} {sum(not o.success for _, o in run.history):4d} "
              f"{best.return_:7.4f} {J0:7.1f} {best.J:7.1f} {J0 / best.J:5.1f} "
              f"{acceleration_integral(task, w0):8.1f} {acceleration_integral(task, best.w):8.1f} "
              f"{time.perf_counter() - t0:5.1f}", flush=True)


if __name__ == "__main__":
    import sys

    if "--sweep" in sys.argv[1:]:
        sweep()
        raise SystemExit(0)
    task = make_task()
    iv = task.contacts.intervals[0]
    print(f"contact {iv.start:.2f}-{iv.end:.2f} s with {', '.join(iv.geoms)}; theta0 = {task.theta0}")
    demo = task.demonstration()
    print(task.demo_report)
    print("demonstration:", task.rollout(demo.w))
