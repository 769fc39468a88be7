"""A whole scene in one MJCF: only the robot's idle joints are locked, the door's survive, and the
compiled placement of objects can be read back."""

import math

import numpy as np
import pytest

from corl.errors import InputError
from corl.mujoco import Robot, body_pose, load_spec, site_pose

mujoco = pytest.importorskip("mujoco")

# A 4-joint arm (two of them to lock: the named wrist with its motor and sensor, and an unnamed
# slide) beside a cabinet turned 90 deg about z, holding a door (hinge) with a latch (unnamed hinge),
# and a free ball. The keyframe covers every joint, so it no longer fits once any is locked.
SCENE = """
<mujoco>
  <compiler angle="radian"/>
  <option timestep="0.001"/>
  <default><geom contype="0" conaffinity="0"/></default>
  <worldbody>
    <body name="base" pos="0 0 0.5">
      <joint name="shoulder" axis="0 0 1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="1"/>
      <body name="forearm" pos="0.3 0 0">
        <joint name="elbow" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.02" mass="0.5"/>
        <body name="hand" pos="0.25 0 0">
          <joint name="wrist" axis="1 0 0"/>
          <geom type="box" size="0.02 0.04 0.02" mass="0.2"/>
          <body name="finger" pos="0.04 0 0">
            <joint type="slide" axis="0 1 0" range="0 0.04"/>
            <geom type="box" size="0.01 0.005 0.01" mass="0.02"/>
          </body>
        </body>
      </body>
    </body>
    <body name="cabinet" pos="1 0 0" euler="0 0 1.5707963267948966">
      <geom type="box" size="0.05 0.05 0.05" pos="0 0 0.05" mass="5"/>
      <body name="door" pos="0.2 0 0.5">
        <joint name="door_hinge" axis="0 0 1"/>
        <geom type="box" size="0.01 0.2 0.3" pos="0 0.2 0" mass="2"/>
        <body name="latch" pos="0 0.35 0">
          <joint axis="1 0 0" damping="0.01"/>
          <geom type="box" size="0.01 0.02 0.02" mass="0.05"/>
          <site name="handle" pos="0.03 0 0"/>
        </body>
      </body>
    </body>
    <body name="ball" pos="0 1 0.1"><freejoint/><geom size="0.05" mass="0.1"/></body>
  </worldbody>
  <actuator><motor name="wrist_motor" joint="wrist"/></actuator>
  <sensor><jointpos name="wrist_angle" joint="wrist"/></sensor>
  <keyframe><key name="home" qpos="0 0 0 0 0 0  0 1 0.1 1 0 0 0"/></keyframe>
</mujoco>
"""
ARM = ("shoulder", "elbow")
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def joints_of(model, body):
    return int(model.body_jntnum[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body)])


def test_only_the_robots_idle_joints_are_locked():
    model = load_spec(SCENE, moving=ARM).compile()
    # the arm: shoulder and elbow move; the wrist (named) and the finger's slide (unnamed) are welded
    assert [joints_of(model, b) for b in ("base", "forearm", "hand", "finger")] == [1, 1, 0, 0]
    # the door's hinge, the latch's unnamed hinge and the ball's free joint are kept
    assert [joints_of(model, b) for b in ("door", "latch", "ball")] == [1, 1, 1]
    assert model.njnt == 5
    # what needed the wrist went with it; the keyframe no longer fitted
    assert (model.nu, model.nsensor, model.nkey) == (0, 0, 0)
    robot = Robot.from_model(model, ARM)
    assert robot.dim == 2
    assert model.jnt_bodyid[robot.id("joint", "door_hinge")] == robot.id("body", "door")
    with pytest.raises(InputError, match="no joint named 'wrist'"):
        robot.id("joint", "wrist")


def test_the_kept_door_swings_under_a_push():
    """A 3 N push at the door's centre of mass turns it as theta = tau t^2 / (2 I) (no damping)."""
    model = load_spec(SCENE, moving=ARM).compile()
    data = mujoco.MjData(model)
    door = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "door")
    hinge = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "door_hinge")
    # closed form: the panel's centre is 0.2 m from the hinge, i.e. at (-0.2, 0, 0) with the
    # cabinet turned; a push along +y gives tau_z = -0.2 * 3 Nm. About the hinge: the panel (2 kg,
    # half sizes 0.01 x 0.2) m (a^2 + b^2) / 3 + m 0.2^2, the latch (0.05 kg, half sizes 0.01 x 0.02)
    # m (a^2 + b^2) / 3 + m 0.35^2 (its own hinge is square to the door's: no coupling at rest)
    tau = -0.2 * 3.0
    inertia = 2 * (0.01**2 + 0.2**2) / 3 + 2 * 0.2**2 + 0.05 * (0.01**2 + 0.02**2) / 3 + 0.05 * 0.35**2
    t = 0.2
    for _ in range(round(t / model.opt.timestep)):
        data.xfrc_applied[door, :3] = [0.0, 3.0, 0.0]
        mujoco.mj_step(model, data)
    angle = data.qpos[model.jnt_qposadr[hinge]]
    expected = 0.5 * tau / inertia * t**2  # -0.106 rad
    # 2%: the lever turns with the door (cos 0.1 rad), and the integrator's O(dt) error
    assert angle == pytest.approx(expected, rel=0.02)


def test_pose_helpers_read_the_compiled_placement():
    spec = load_spec(SCENE, moving=ARM)
    model = spec.compile()
    p, R = body_pose(model, "door")
    np.testing.assert_allclose(p, [1.0, 0.2, 0.5], atol=1e-9)
    np.testing.assert_allclose(R, RZ90, atol=1e-9)
    p, R = site_pose(model, "handle")  # door frame (0.03, 0.35, 0) -> turned by 90 deg about z
    np.testing.assert_allclose(p, [1.0 - 0.35, 0.2 + 0.03, 0.5], atol=1e-9)
    # placed by code before compiling, as other frameworks do: the XML text does not show it
    spec.body("cabinet").pos = [2.0, 0.5, 0.1]
    model = spec.compile()
    robot = Robot.from_model(model, ARM)
    p, R = body_pose(robot, "door")  # a Robot works too
    np.testing.assert_allclose(p, [2.0, 0.5 + 0.2, 0.1 + 0.5], atol=1e-9)
    np.testing.assert_allclose(R, RZ90, atol=1e-9)
    # with data: the current pose, the door opened by 0.5 rad
    data = mujoco.MjData(model)
    data.qpos[model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "door_hinge")]] = 0.5
    mujoco.mj_kinematics(model, data)
    _, R_open = body_pose(model, "door", data)
    assert math.acos((np.trace(R.T @ R_open) - 1) / 2) == pytest.approx(0.5, abs=1e-9)


def test_pose_helper_errors():
    model = load_spec(SCENE, moving=ARM).compile()
    with pytest.raises(InputError, match=r"no body named 'dor'.*'door'"):
        body_pose(model, "dor")
    with pytest.raises(InputError, match="no site named 'door'"):
        site_pose(model, "door")
    with pytest.raises(InputError, match="needs a compiled mujoco.MjModel"):
        body_pose("scene.xml", "door")


def test_ambiguous_robot_is_refused_with_what_would_be_welded():
    # naming the door's hinge as moving, as the old API required, spans two trees: which is the robot?
    with pytest.raises(InputError, match="ambiguous") as info:
        load_spec(SCENE, moving=ARM + ("door_hinge",))
    message = str(info.value)
    assert "wrist" in message and "<unnamed joint of body 'finger'>" in message
    assert "<unnamed joint of body 'latch'>" in message and "robot_root=" in message
    assert "\n" not in message
    # naming the robot's root settles it: the arm's idle joints go, the latch stays
    model = load_spec(SCENE, moving=ARM + ("door_hinge",), robot_root="base").compile()
    assert [joints_of(model, b) for b in ("hand", "finger", "door", "latch")] == [0, 0, 1, 1]
    # listing every joint of both trees welds nothing, so nothing is ambiguous
    everything = [j.name for j in mujoco.MjSpec.from_string(SCENE).joints if j.name]
    assert load_spec(SCENE, moving=everything[:4] + ["door_hinge"], robot_root=("base", "cabinet")).compile().njnt == 5


def test_robot_root_errors():
    with pytest.raises(InputError, match=r"robot_root 'arm' is not a body of the MJCF.*'base'"):
        load_spec(SCENE, moving=ARM, robot_root="arm")
    with pytest.raises(InputError, match="robot_root needs moving="):
        load_spec(SCENE, robot_root="base")
    with pytest.raises(InputError, match="moving is empty"):
        load_spec(SCENE, moving=())
    with pytest.raises(InputError, match="robot_root is for MJCF scenes"):
        load_spec('<robot name="r"><link name="a"/></robot>', moving=(), robot_root="a")


def test_robot_root_empty_moving_locks_the_whole_robot():
    model = load_spec(SCENE, moving=(), robot_root="base").compile()
    assert [joints_of(model, b) for b in ("base", "forearm", "door", "latch")] == [0, 0, 1, 1]
    # nested roots: the hand's subtree is inside the base's, its joints are locked once
    model = load_spec(SCENE, moving=ARM, robot_root=("base", "hand")).compile()
    assert [joints_of(model, b) for b in ("base", "hand", "finger", "door")] == [1, 0, 0, 1]
