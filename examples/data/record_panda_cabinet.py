"""Record a teleoperated demonstration of closing the cabinet door of ``examples/panda_cabinet_demo.py``.

A teleoperator drives the Panda's closed fingertips to the door's face 5 cm from the hinge and
pushes it shut along its arc (and 5 mm on, against its stop), the hand square to the face:
task-space waypoints solved by IK, joined linearly and played at the controller's 500 Hz by the
servos. The script logs the joint positions the teleoperation commanded (the 7 arm joints and the
gripper width) every control step, nothing else: no contact, no door angle, no theta. The result is
``examples/data/panda_cabinet_demo.npz`` (``t`` (T,) s, ``q`` (T, 8), ``joints`` (8,)).

Regenerate it (from the repository root):  python -m examples.data.record_panda_cabinet
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from corl.mujoco import Kinematics, Target, piecewise_linear, save_recording, servo_controller, solve_waypoints, track

OUT = Path(__file__).with_name("panda_cabinet_demo.npz")
ARM_AND_GRIPPER = tuple(f"panda_joint{i}" for i in range(1, 8)) + ("gripper_width_m",)
R_DEMO, WIDTH, DT, DURATION = 0.05, 0.01, 0.002, 2.8
# hand pointing at the shut door (+x), the fingertips side by side along it
HAND_FORWARD = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])


def rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def face_target(q_door: float, back: float = 0.0) -> Target:
    """The fingertips on the door's face R_DEMO from the hinge (``back`` m in front of it), door at ``q_door``."""
    from examples.panda_cabinet_demo import AJAR, HINGE, THICK

    turn = rot_z(AJAR - q_door)
    return Target(HINGE + turn @ np.array([-THICK / 2 - back, R_DEMO, 0.0]), turn @ HAND_FORWARD, gripper=WIDTH)


def record(path=OUT) -> Path:
    """Play the teleoperated waypoints and save the commanded joint positions to ``path``."""
    from examples.panda_cabinet_demo import AJAR, build_robot

    robot = build_robot()
    kin = Kinematics(robot)
    tips, hand = kin.site("panda_leftfinger_tip", "panda_rightfinger_tip"), kin.site("hand")
    plan = [(0.0, 0.0, 0.12), (0.8, 0.0, 0.04), (1.2, 0.0, 0.0)]  # (time, door angle, back-off)
    plan += [(1.2 + 1.2 * f, AJAR * f, -0.005 * f) for f in np.linspace(0, 1, 7)[1:]] + [(DURATION, AJAR, -0.005)]
    seed = np.array([0.0, 0.3, 0.0, -1.8, 0.0, 2.1, 0.785, WIDTH])
    knots = solve_waypoints(kin, tips, [face_target(a, b) for _, a, b in plan], seed, start=2, rotation_frame=hand)
    q = piecewise_linear([t for t, _, _ in plan], knots, DURATION, DT)
    data, _ = track(robot, servo_controller(robot), q, DURATION)
    door = data.qpos[robot.model.jnt_qposadr[robot.id("joint", "door_hinge")]]
    print(f"played: door at {door:.3f} rad of {AJAR} (shut)")
    return save_recording(path, np.arange(len(q)) * DT, q, ARM_AND_GRIPPER)


if __name__ == "__main__":
    print("wrote", record())
