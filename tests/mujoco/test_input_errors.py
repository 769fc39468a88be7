"""The kit refuses bad input early, in one line that says what was wrong and what to do."""

import numpy as np
import pytest

from corl.errors import InputError
from corl.mujoco import (Kinematics, Robot, Target, add_force_sensor, add_servos, example_robot_dir, load_spec,
                         solve_ik)

mujoco = pytest.importorskip("mujoco")

BODY = '<body name="{name}"><joint name="{name}_j"/><geom size="0.1" mass="1"/></body>'
URDF_MESH = """<robot name="r"><link name="a"><collision><geometry><mesh filename="{path}"/></geometry></collision>
  <inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" ixy="0" ixz="0" iyz="0"/></inertial></link></robot>"""


def refused(match, call, *args, **kwargs) -> str:
    """The message of the InputError that ``call`` raises; it must be one line."""
    with pytest.raises(InputError, match=match) as info:
        call(*args, **kwargs)
    assert "\n" not in str(info.value)
    return str(info.value)


def test_malformed_mjcf_and_urdf_text():
    refused("cannot read the MJCF: XML parse error", load_spec, "<mujoco><worldbody><body")
    refused("cannot read the MJCF: .*unrecognized attribute: 'sizee'.*fix the XML", load_spec,
            "<mujoco><worldbody><geom sizee='1'/></worldbody></mujoco>")
    refused("cannot read the URDF", load_spec, '<robot name="r"><link name="a"></robot>')


def test_missing_include_and_mesh(tmp_path):
    scene = tmp_path / "scene.xml"
    scene.write_text('<mujoco><include file="robot.xml"/></mujoco>')
    refused("cannot read the MJCF: .*robot.xml.*check that the file exists", load_spec, scene)
    refused("give the path of the XML file rather than its text", load_spec, scene.read_text())
    scene.write_text('<mujoco><asset><mesh name="m" file="hand.stl"/></asset>'
                     '<worldbody><body><joint/><geom type="mesh" mesh="m"/></body></worldbody></mujoco>')
    refused("does not compile: .*hand.stl.*check that the file exists", load_spec, scene)
    urdf = tmp_path / "r.urdf"
    urdf.write_text(URDF_MESH.format(path="meshes/hand.stl"))
    refused("cannot read the URDF: .*hand.stl.*check the mesh paths", load_spec, urdf)


def test_duplicate_names():
    text = f"<mujoco><worldbody>{BODY.format(name='a')}{BODY.format(name='a')}</worldbody></mujoco>"
    refused("repeated name 'a'.*unique name", load_spec, text)



def test_a_spec_that_does_not_compile():
    spec = load_spec(f"<mujoco><worldbody>{BODY.format(name='a')}</worldbody></mujoco>")
    spec.add_actuator(name="m", target="nope", trntype=mujoco.mjtTrn.mjTRN_JOINT)  # MjSpec API: not checked
    refused("the scene does not compile: .*unknown transmission target 'nope'", Robot.from_spec, spec, ["a_j"])


def test_servos_and_sensors_check_names_when_added(tiny):
    spec = load_spec(tiny.xml, moving=tiny.joints)  # the fingers are locked
    refused(r"no joint 'j4' in the spec .*'j1', 'j2', 'j3'", add_servos, spec, ("j1", "j4"), (1.0, 1.0),
            (0.1, 0.1), (1.0, 1.0))
    assert len(spec.actuators) == 0  # nothing half-added
    refused("no joint 'fl' in the spec .was it locked by load_spec", add_servos, spec, ("fl",), (1.0,), (0.1,),
            (1.0,))
    add_servos(spec, ("j1",), (1.0,), (0.1,), (1.0,))
    refused("'j1' has a servo already", add_servos, spec, ("j1",), (1.0,), (0.1,), (1.0,))
    refused("no site 'wrist' in the spec.*'ft'", add_force_sensor, spec, "wrist")
    add_force_sensor(spec, "ft")
    refused("'ft' has a force sensor already", add_force_sensor, spec, "ft")
    refused("needs a mujoco.MjSpec", add_force_sensor, spec.compile(), "ft")
    refused("needs a mujoco.MjSpec", add_servos, "arm.xml", ("j1",), (1.0,), (0.1,), (1.0,))
    ball = load_spec("<mujoco><worldbody><body><joint name='b' type='ball'/><geom size='.1'/></body></worldbody></mujoco>")
    refused("'b' is not a hinge or slide", add_servos, ball, ("b",), (1.0,), (0.1,), (1.0,))


def test_nan_in_q_is_refused(arm):
    kin = Kinematics(arm)
    tool = kin.site("tool")
    q = np.array([0.4, -0.7, 0.9, 0.03])
    kin.position(q, tool)
    bad = q.copy()
    bad[1] = np.nan
    refused(r"q contains NaN or inf at \[1\]", kin.position, bad, tool)
    refused("NaN or inf", kin.position_jacobian, np.full(4, np.inf), tool)
    refused("NaN or inf", arm.check_q, bad)
    target = Target(kin.position(q, tool))
    refused("NaN or inf", solve_ik, kin, tool, target, bad)
    refused("Target.gripper must be a finite", Target, np.zeros(3), gripper=float("nan"))
    refused("Target.gripper must be a finite", Target, np.zeros(3), gripper="open")
    assert np.all(np.isfinite(kin.position(q, tool)))  # the cache still answers the last good q


@pytest.mark.parametrize("name", ["../../../../..", "..", ".", "", "panda_description/../..", "/etc",
                                  "a\\b", 3])
def test_example_robot_dir_takes_one_plain_folder_name(name):
    refused("not a plain folder name", example_robot_dir, name)
