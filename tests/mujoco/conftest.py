"""A tiny MJCF robot for the kit's tests: three hinges, a two-finger slide gripper, a force site."""

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

ARM_XML = """
<mujoco>
  <compiler angle="radian"/>
  <option timestep="0.002" integrator="implicitfast"/>
  <worldbody>
    <geom name="floor" type="plane" size="2 2 0.1" contype="0" conaffinity="1"/>
    <body name="base" pos="0 0 0.3">
      <joint name="j1" type="hinge" axis="0 0 1" range="-3 3" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0.3 0 0" size="0.02" mass="1" contype="0" conaffinity="0"/>
      <body name="l2" pos="0.3 0 0">
        <joint name="j2" type="hinge" axis="0 1 0" range="-2 2" damping="0.1"/>
        <geom type="capsule" fromto="0 0 0 0.25 0 0" size="0.02" mass="0.5" contype="0" conaffinity="0"/>
        <body name="hand" pos="0.25 0 0" euler="0 0 0.3">
          <joint name="j3" type="hinge" axis="1 0 0" damping="0.1"/>
          <geom name="palm" type="box" size="0.02 0.04 0.02" mass="0.2" contype="0" conaffinity="0"/>
          <site name="ft" pos="0 0 0"/>
          <site name="tool" pos="0.05 0.01 0" euler="0.2 0.4 0"/>
          <body name="finger_l" pos="0.04 0 0">
            <joint name="fl" type="slide" axis="0 1 0" range="0 0.04"/>
            <geom name="tip_l" type="box" size="0.01 0.005 0.01" mass="0.02" contype="2" conaffinity="0"/>
            <site name="tip_l" pos="0.01 0 0"/>
          </body>
          <body name="finger_r" pos="0.04 0 0">
            <joint name="fr" type="slide" axis="0 -1 0" range="0 0.04"/>
            <geom name="tip_r" type="box" size="0.01 0.005 0.01" mass="0.02" contype="2" conaffinity="0"/>
            <site name="tip_r" pos="0.01 0 0"/>
          </body>
        </body>
      </body>
    </body>
    <body name="crate" pos="1.2 0 0.05">
      <freejoint/>
      <geom name="crate" type="box" size="0.05 0.05 0.05" mass="2"/>
    </body>
  </worldbody>
</mujoco>
"""

ARM_JOINTS = ("j1", "j2", "j3")
KP, KV, EFFORT = (400.0, 300.0, 100.0), (8.0, 6.0, 2.0), (200.0, 200.0, 50.0)


def gripper():
    from corl.mujoco import Gripper

    # c is the opening width: each finger slides c / 2
    return Gripper(("fl", "fr"), angle_of=lambda c: 0.5 * np.asarray(c), slope=lambda a: 2.0 + 0.0 * np.asarray(a),
                   lower=0.0, upper=0.08)


@pytest.fixture(scope="session")
def arm():
    """The tiny robot with servos and a force sensor at ``ft``: (Robot, kp, kv)."""
    from corl.mujoco import Robot, add_force_sensor, add_joint_equality, add_servos, load_spec

    spec = load_spec(ARM_XML, moving=ARM_JOINTS + ("fl", "fr"))
    add_servos(spec, ARM_JOINTS, KP, KV, EFFORT)
    add_servos(spec, ("fl",), (200.0,), (2.0,), (20.0,))
    add_joint_equality(spec, "fr", "fl", name="couple")
    add_force_sensor(spec, "ft")
    return Robot.from_spec(spec, ARM_JOINTS, gripper())


@pytest.fixture(scope="session")
def tiny():
    """The tiny model's XML, joint names and servo gains."""
    from types import SimpleNamespace

    return SimpleNamespace(xml=ARM_XML, joints=ARM_JOINTS, kp=KP, kv=KV)
