"""Loading with locked joints, the PD rollout with gravity compensation, force readings, video."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from corl.errors import InputError
from corl.mujoco import (Camera, ForceSensor, FrameRecorder, PDController, Robot, contact_force,
                         load_spec, rendering_available, touching, track)

mujoco = pytest.importorskip("mujoco")

URDF = """<robot name="two">
  <link name="base"/>
  <link name="a"><inertial><mass value="1"/><origin xyz="0 0 0.1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.05 0.05 0.2"/></geometry></collision></link>
  <link name="b"><inertial><mass value="0.5"/><origin xyz="0 0 0.1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="c"><inertial><mass value="0.2"/><origin xyz="0 0 0.05"/><inertia ixx="0.001" iyy="0.001" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="ja" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="10" velocity="1"/></joint>
  <joint name="jb" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="10" velocity="1"/></joint>
  <joint name="jc" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0 0 0.2"/><axis xyz="1 0 0"/><limit lower="-2" upper="2" effort="10" velocity="1"/></joint>
</robot>"""


def test_urdf_locks_and_fuses():
    spec = load_spec(URDF, lock=["jc"])
    model = spec.compile()
    assert model.njnt == 2
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "c") == -1  # fused into b
    robot = Robot.from_model(model, ["ja", "jb"])
    np.testing.assert_allclose(robot.lower, [-2, -2])
    with pytest.raises(InputError, match="'nope' is not in the URDF"):
        load_spec(URDF, moving=["ja", "nope"])


def test_mjcf_locks_joints(tiny):
    spec = load_spec(tiny.xml, lock=["j3"])
    model = spec.compile()
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "j3") == -1
    with pytest.raises(InputError, match="was it locked"):
        Robot.from_model(model, tiny.joints)


def test_missing_file():
    with pytest.raises(InputError, match="does not exist"):
        load_spec("/nonexistent/robot.urdf")


def test_pd_rollout_with_gravity_compensation_tracks(arm, tiny):
    """A smooth reference is tracked to within a few mrad; at rest gravity is cancelled exactly."""
    dt = arm.model.opt.timestep
    t = np.arange(0, 1.0 + dt / 2, dt)
    q0 = np.array([0.2, -0.6, 0.4, 0.03])
    ref = q0 + np.outer(0.5 * (1 - np.cos(np.pi * t / 1.0)), [0.3, 0.4, -0.2, 0.0])
    log = []
    data, q_ref = track(arm, PDController(arm, tiny.kp, tiny.kv), ref, 1.0, on_step=lambda k, d: log.append(d.qpos[arm.qpos].copy()))
    err = np.abs(np.array(log) - q_ref[:, :3]).max()
    assert err < 5e-3
    # holding still: with gravity compensation, the servos need no steady-state error
    hold = np.repeat(q0[None], 400, axis=0)
    data, _ = track(arm, PDController(arm, tiny.kp, tiny.kv), hold, 0.8)
    np.testing.assert_allclose(data.qpos[arm.qpos], q0[:3], atol=1e-6)
    assert data.qpos[arm.gripper_qpos] == pytest.approx([0.015, 0.015], abs=1e-4)  # width 3 cm


def test_force_sensor_reads_the_weight_below_it(arm, tiny):
    sensor = ForceSensor(arm, "ft")
    data = mujoco.MjData(arm.model)
    q = np.array([0.3, 0.5, 0.7, 0.02])
    pd = PDController(arm, tiny.kp, tiny.kv)
    pd.initialise(data, q)  # at rest on its set-points, gravity compensated: no acceleration
    pd.apply(data, pd.setpoints(q[None], np.zeros((1, 4)))[0])
    mujoco.mj_forward(arm.model, data)
    pd.compensate(data)
    mujoco.mj_forward(arm.model, data)
    assert np.abs(data.qacc[arm.dofs]).max() < 1e-6
    raw = sensor.raw(data)
    # at rest the sensor carries the weight of the hand and fingers: |f_raw| = m g
    assert np.linalg.norm(raw) == pytest.approx(sensor.mass * 9.81, rel=1e-6)
    assert np.linalg.norm(sensor.interaction(data)) < 1e-9 * sensor.mass * 9.81 + 1e-12


def test_contact_force_holds_the_crate(arm):
    model = arm.model
    data = mujoco.MjData(model)
    for _ in range(500):  # let the 2 kg crate settle on the floor
        mujoco.mj_step(model, data)
    crate = [arm.id("geom", "crate")]
    floor = [arm.id("geom", "floor")]
    assert touching(data, crate, floor)
    np.testing.assert_allclose(contact_force(model, data, crate, floor), [0, 0, 2 * 9.81], atol=1e-3 * 2 * 9.81)
    np.testing.assert_allclose(contact_force(model, data, floor, crate), [0, 0, -2 * 9.81], atol=1e-3 * 2 * 9.81)
    assert not touching(data, [arm.id("geom", "tip_l")], crate)
    assert np.all(contact_force(model, data, [arm.id("geom", "tip_l")], crate) == 0.0)


def test_video_frames_or_skip(arm, tiny):
    ok, why = rendering_available()
    if not ok and "MUJOCO_GL" not in os.environ:  # MuJoCo reads MUJOCO_GL once: try EGL in a fresh process
        out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs",
                              f"{__file__}::test_video_frames_or_skip"], capture_output=True, text=True,
                             env={**os.environ, "MUJOCO_GL": "egl"}, cwd=Path(__file__).parent)
        if "1 passed" in out.stdout:
            return
        assert "1 skipped" in out.stdout, out.stdout[-2000:] + out.stderr[-2000:]
        pytest.skip(f"no rendering here, nor with MUJOCO_GL=egl: {why}")
    if not ok:
        pytest.skip(why)
    rec = FrameRecorder(arm.model, Camera(lookat=(0.3, 0, 0.3), distance=1.5), fps=25, width=64, height=48)
    track(arm, PDController(arm, tiny.kp, tiny.kv), np.array([[0.2, -0.6, 0.4, 0.03]]), 0.2, on_step=rec)
    frames = rec.close()
    assert frames.shape == (6, 48, 64, 3)  # 0.2 s at 25 fps, and the first frame
    assert frames.std() > 1.0  # not a blank image


def test_a_machine_that_cannot_render_says_so_quietly():
    # without MUJOCO_GL and without a display MuJoCo tries GLFW: it warned, Renderer raised and the
    # half-made renderer's __del__ printed a traceback into `corl run`'s output; now only the reason
    code = ("import gc, mujoco\n"
            "from corl.mujoco.video import make_renderer, rendering_available\n"
            "m = mujoco.MjModel.from_xml_string(\"<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>\")\n"
            "try:\n"  # too large for the offscreen buffer: refused, and not remembered as 'cannot render'
            "    make_renderer(m, height=8, width=100000)\n"
            "except ValueError as exc:\n"
            "    assert 'offscreen buffer' in str(exc), exc\n"
            "ok, why = rendering_available()\n"
            "assert ok or not why.startswith('ValueError'), why\n"
            "try:\n"
            "    make_renderer(m, height=8, width=8).close(); made = True\n"
            "except Exception as exc:\n"
            "    made = False; assert str(exc) and type(exc).__name__ in why, (exc, why)\n"
            "gc.collect()\n"
            "assert made == ok\n"
            "print(ok)\n")
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert out.returncode == 0 and out.stdout.strip() in ("True", "False"), out.stderr[-2000:]
    assert out.stderr == ""  # no GLFWError warning, no "Exception ignored in: Renderer.__del__"


def test_importing_the_kit_does_not_import_mujoco():
    import subprocess
    import sys

    code = "import sys, corl.mujoco; print('mujoco' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_servo_and_controller_errors(arm, tiny):
    from corl.mujoco import add_servos

    spec = load_spec(tiny.xml, moving=tiny.joints)
    with pytest.raises(InputError, match="kp has 2 values, expected one per joint"):
        add_servos(spec, tiny.joints, (1.0, 2.0), tiny.kv, (1.0, 1.0, 1.0))
    bare = Robot.from_spec(load_spec(tiny.xml, moving=tiny.joints), tiny.joints)
    with pytest.raises(InputError, match="no actuator named 'servo_j1'"):
        PDController(bare, tiny.kp, tiny.kv)
    with pytest.raises(InputError, match=r"reference has shape \(5, 3\), expected \(N, 4\)"):
        track(arm, PDController(arm, tiny.kp, tiny.kv), np.zeros((5, 3)), 0.01)
