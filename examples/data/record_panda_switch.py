"""Record the switch demonstration of ``examples/panda_switch.py`` as a robot would log it.

The hand-written task's demonstration (IK waypoints, a B-spline, projected onto its h) is tracked by
the simulated Panda's servos, and at the controller's rate (500 Hz) the script logs what a robot's
joint-state topic gives: the 7 arm joints' positions and the gripper's opening width (m, twice the
first finger joint). Nothing else: no contact, no paddle angle, no theta. The result is
``examples/data/panda_switch_demo.npz`` (``t`` (T,) s, ``q`` (T, 8), ``joints`` (8,)), the input of
``examples/panda_switch_demo.py``.

Regenerate it (from the repository root):  python -m examples.data.record_panda_switch
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from corl.mujoco import save_recording

OUT = Path(__file__).with_name("panda_switch_demo.npz")


def record(path=OUT) -> Path:
    """Track the demonstration and save the joint log to ``path``."""
    from examples.panda_switch import DT, make_task

    task = make_task()
    robot = task.robot
    finger = robot.gripper_qpos[0]
    rows = []

    def log(k, data):  # every control step, as a robot's joint-state log
        rows.append(np.append(data.qpos[robot.qpos], 2.0 * data.qpos[finger]))

    task.run(task.demonstration().w, on_step=log)
    q = np.array(rows)
    return save_recording(path, np.arange(len(q)) * DT, q, task.joint_names)


if __name__ == "__main__":
    print("wrote", record())
