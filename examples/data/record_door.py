"""Record the PR2 door demonstration of :mod:`corl.tasks.door` as a robot would log it.

The door task's scripted demonstration (IK waypoints joined piecewise-linearly, fitted by its
B-spline) is tracked by the simulated PR2's servos in the door's own rollout (latch included), and
at the controller's rate (500 Hz) the script logs what a PR2's arm and gripper controllers publish as
their *desired* state: the 7 right-arm joints' commanded positions and the gripper's commanded
opening width (m, the gap between the fingertip pads). Nothing else: no contact, no door or handle
angle, no theta. The result is ``examples/data/door_demo.npz`` (``t`` (T,) s, ``q`` (T, 8),
``joints`` (8,)), the input of ``benchmarks/door_from_recording.py``.

Why the desired and not the measured positions (measured on this scene):

* the gripper closed on the 22 mm bar stops at 20.4 mm; a reference at 20.4 mm does not squeeze,
  and the demonstration's motion with it fails (the handle turns 0.22 rad of the latch's 0.40, the
  grip slips): the grip force is only in the command;
* the arm lags its command while it presses the sprung handle; a reference fitted to the measured
  positions lags once more when tracked, and presses the handle to 0.38 rad, short of the latch.

A robot that is taught kinesthetically logs only measured positions; its demonstration then needs
a reference that leads them (a stiffer controller, or a recording replayed once and corrected).

Regenerate it (from the repository root):  python -m examples.data.record_door
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from corl.mujoco import save_recording

OUT = Path(__file__).with_name("door_demo.npz")


def record(path=OUT) -> Path:
    """Track the door's demonstration and save the controllers' desired positions to ``path``."""
    from corl.tasks.door.sim import rollout
    from corl.tasks.door.task import DoorTask, grasp_instant

    task = DoorTask()
    scene = task.scene
    t, q_ref = task.reference(task.demonstration().w)
    dt = scene.model.opt.timestep
    rows = []

    def log(time, _):  # every control step: the controllers' desired state
        rows.append(q_ref[int(round(time / dt))])

    result = rollout(q_ref, duration=task.duration, t_contact=grasp_instant(t, q_ref), scene=scene,
                     on_frame=log, frame_every=1)
    q = np.array(rows, dtype=np.float32).astype(float)
    print(f"demonstration tracked: success {result.success}, door {result.hinge_final:.2f} rad, "
          f"wrist force {result.force_mean:.1f} N")
    return save_recording(path, np.arange(len(q)) * dt, q, task.joint_names)


if __name__ == "__main__":
    print("wrote", record())
