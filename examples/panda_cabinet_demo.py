"""A task written from a recording only: the Panda pushes an ajar cabinet door shut.

The scene: the Panda of ``example-robot-data`` in front of a cabinet door (24 cm wide, 20 cm high)
on a vertical hinge, held ajar at 0.4 rad by a spring that needs a torque to close it. The recording
(``examples/data/panda_cabinet_demo.npz``, made by ``examples/data/record_panda_cabinet.py``) is a
teleoperator's: IK waypoints of the closed fingertips on the door's face, 5 cm from the hinge,
played at the controller's 500 Hz while the door turns shut. Nothing of h is written here:
:func:`corl.mujoco.task_from_recording` finds the contact and derives theta (where on the face the
fingertips push: along the door from the hinge, and up), h, theta_of, J and w0. What is written:

* S : the door shut (within 0.05 rad) with the fingertips whole on its face the whole push
* R : ``1 - F / F_REF``, F the mean contact force from the first touch on (N): the spring needs a
      torque, so farther from the hinge needs less force, until the fingers slip off the edge

Run it:  corl run examples.panda_cabinet_demo:make_task --seed 0
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from corl.mujoco import (Gripper, Robot, add_joint_equality, add_servos, example_robot_dir, load_spec,
                         task_from_recording)

RECORDING = Path(__file__).with_name("data") / "panda_cabinet_demo.npz"
ARM = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGERS = ("panda_finger_joint1", "panda_finger_joint2")
HINGE = np.array([0.62, -0.15, 0.35])  # the door's vertical hinge axis passes here
WIDTH, HEIGHT, THICK = 0.24, 0.20, 0.02  # m; the door reaches from the hinge along +y, shut
AJAR, SHUT = 0.4, 0.05                   # rad: open that far on its stop; shut within SHUT of closed
STIFFNESS = 1.0                          # Nm/rad; the spring's rest lies 0.3 rad beyond the stop
F_REF = 16.0                             # N, about the demonstration's force: R ~ 0 there
TIP_HALF = 0.009                         # m, half a fingertip pad


def build_robot() -> Robot:
    """The Panda with servos and the cabinet door (a fresh model per call)."""
    import mujoco

    root = example_robot_dir("panda_description")
    spec = load_spec(root / "urdf" / "panda.urdf", moving=ARM + FINGERS,
                     package_dirs={"package://example-robot-data/robots/panda_description/": root})
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for body in spec.bodies:  # only the rubber fingertips touch anything, and only the door
        for geom in body.geoms:
            geom.contype = geom.conaffinity = 0
        if body.name in ("panda_leftfinger", "panda_rightfinger"):
            tip = max(body.geoms, key=lambda g: g.pos[2])
            tip.contype, tip.name, tip.friction = 2, f"{body.name}_tip", [1.0, 0.005, 0.0001]
            side = 1.0 if body.name == "panda_leftfinger" else -1.0  # sites for the teleoperator's IK
            body.add_site(name=f"{body.name}_tip", pos=[0.0, side * 0.00758, 0.0545], size=[0.003, 0, 0])
    spec.body("panda_link7").add_site(name="hand", pos=[0, 0, 0.107],
                                      quat=[math.cos(math.pi / 8), 0, 0, -math.sin(math.pi / 8)])
    for name, arm in zip(ARM, (0.1, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05)):
        spec.joint(name).armature = arm
    add_servos(spec, ARM, (2000, 2000, 1500, 1500, 500, 500, 300), (40, 40, 30, 30, 8, 8, 5), (87,) * 4 + (12,) * 3)
    add_servos(spec, FINGERS[:1], (200.0,), (5.0,), (40.0,))
    add_joint_equality(spec, FINGERS[1], FINGERS[0], name="fingers")
    # the door's frame turns with it: q = 0 ajar (the spring holds it on its stop), q = AJAR shut
    door = spec.worldbody.add_body(name="cabinet_door", pos=HINGE.tolist(),
                                   quat=[math.cos(AJAR / 2), 0.0, 0.0, math.sin(AJAR / 2)])
    door.add_joint(name="door_hinge", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, -1], range=[0.0, AJAR],
                   limited=True, stiffness=STIFFNESS, springref=-0.3, damping=0.3, armature=0.002)
    door.add_geom(name="cabinet_door", type=mujoco.mjtGeom.mjGEOM_BOX, size=[THICK / 2, WIDTH / 2, HEIGHT / 2],
                  pos=[0, WIDTH / 2, 0], mass=0.5, rgba=[0.6, 0.45, 0.3, 1], contype=0, conaffinity=2)
    spec.worldbody.add_light(pos=[0.3, 0, 2.0], dir=[0, 0, -1])
    gripper = Gripper(FINGERS, angle_of=lambda c: 0.5 * np.asarray(c), slope=lambda a: 2.0 + 0.0 * np.asarray(a),
                      lower=0.0, upper=0.08)
    return Robot.from_spec(spec, ARM, gripper)


def success(log) -> bool:
    """The door shut, the fingertips stayed whole on its face and touched it 80 % of the time."""
    touch = log["touch"]
    if not touch.any():
        return False
    after = slice(int(np.argmax(touch)), None)
    along, up, gap = log["point"][after, 1], log["point"][after, 2], log["point"][after, 0] + THICK / 2
    on_face = np.all((along > TIP_HALF) & (along < WIDTH - TIP_HALF) & (np.abs(up) < HEIGHT / 2 - TIP_HALF)
                     & (np.abs(gap) < 0.02))
    return bool(log["object_q"][-1, 0] > AJAR - SHUT and on_face and touch[after].mean() > 0.8)


def return_(log) -> float:
    """``1 - F / F_REF``, F the mean contact force from the first touch on (N)."""
    return 1.0 - float(log["force"][int(np.argmax(log["touch"])):].mean()) / F_REF


def method_settings():
    """GP length scales in metres of theta, the trust region in radians of w."""
    from corl.settings import ClassifierConfig, CORLConfig, MethodSettings, RegressionConfig

    return MethodSettings(regression=RegressionConfig(lengthscale=0.04, signal_std=0.5, noise_std=0.01),
                          classifier=ClassifierConfig(lengthscale=0.02, signal_std=10.0, prior_mean=-7.0),
                          corl=CORLConfig(eps_max=0.3, eps_w=1e-4, max_rounds=4, max_optimization_steps=12,
                                          max_rl_trials=25))


def make_task():
    """The cabinet task derived from the recording: theta = where on the face (along the door, up)."""
    return task_from_recording(build_robot(), None, RECORDING, "cabinet_door", return_=return_, success=success,
                               name="panda_cabinet_demo", hold_orientation=True, settings=method_settings())


if __name__ == "__main__":
    task = make_task()
    iv = task.contacts.intervals[0]
    print(f"contact {iv.start:.2f}-{iv.end:.2f} s with {', '.join(iv.geoms)}; theta0 = {task.theta0}")
    print(task.theta_labels, task.theta_bounds)
    demo = task.demonstration()
    print(task.demo_report)
    log = task.run(demo.w)
    print("demonstration:", task.rollout(demo.w), "force", log["force"][int(np.argmax(log["touch"])):].mean(),
          "door", log["object_q"][-1, 0])
