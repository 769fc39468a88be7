"""Physics of the simulated door task: latch, wrist sensor, demonstration, contact point, FK."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from corl.tasks.door.controller import PDController, dense_reference  # noqa: E402
from corl.tasks.door.kinematics import Kinematics  # noqa: E402
from corl.tasks.door.sim import OPEN_THRESHOLD, rollout  # noqa: E402


def _simulate(scene, reference, seconds, on_step=None, hinge_torque=0.0):
    """Track ``reference`` (N, 8) for ``seconds``; optionally push the door with ``hinge_torque``."""
    model, data = scene.model, mujoco.MjData(scene.model)
    ctrl = PDController(scene)
    q_ref, dq_ref = dense_reference(reference, seconds, model.opt.timestep)
    u = ctrl.setpoints(q_ref, dq_ref)
    ctrl.initialise(data, q_ref[0])
    mujoco.mj_forward(model, data)
    for k in range(1, len(u)):
        data.ctrl[:] = u[k]
        ctrl.compensate(data)
        data.qfrc_applied[scene.hinge_dof] = hinge_torque
        mujoco.mj_step(model, data)
        if on_step is not None:
            on_step(k, data)
    return data


@pytest.mark.parametrize("torque", [-15.0, 15.0])
def test_latch_holds_when_the_handle_is_not_pressed(scene, demo, torque):
    # 15 Nm on the hinge is about 20 N at the handle, pulling (+) or pushing (-).
    data = _simulate(scene, demo.knots[:1], 1.0, hinge_torque=torque)
    assert data.eq_active[scene.latch_eq] == 1
    assert abs(data.qpos[scene.hinge_qpos]) < 0.02
    assert abs(data.qpos[scene.handle_qpos]) < 0.02


def test_door_swings_once_the_latch_is_off(scene, demo):
    model, data = scene.model, mujoco.MjData(scene.model)
    data.eq_active[scene.latch_eq] = 0
    for _ in range(250):
        data.qfrc_applied[scene.hinge_dof] = 15.0
        mujoco.mj_step(model, data)
    assert data.qpos[scene.hinge_qpos] > 0.05


def test_wrist_sensor_reads_the_hand_weight_at_rest(scene, demo):
    data = _simulate(scene, demo.knots[:1], 0.6)
    weight = scene.hand_mass * -scene.model.opt.gravity[2]
    force = data.sensordata[scene.force_adr:scene.force_adr + 3]
    assert 1.2 < scene.hand_mass < 1.6  # the PR2 gripper
    assert np.linalg.norm(force) == pytest.approx(weight, rel=0.03)
    # and it points up in the world: the wrist holds the hand against gravity
    world = data.site_xmat[scene.ft_site].reshape(3, 3) @ force
    assert world[2] == pytest.approx(weight, rel=0.05)


@pytest.mark.slow
def test_demonstration_succeeds(scene, demo):
    result = rollout(demo.reference(), t_contact=demo.t_contact, scene=scene)
    assert result.success
    assert result.hinge_final > OPEN_THRESHOLD
    assert result.held and result.pad_contact_fraction > 0.95
    assert result.t_release > demo.t_contact
    assert 3.0 < result.force_mean < 40.0
    # before the grasp the interaction force is small (the hand's weight is compensated)
    free = result.times < 1.2
    assert np.median(result.force[free]) < 3.0


@pytest.mark.slow
def test_a_rollout_is_deterministic(scene, demo):
    ref = demo.reference()
    a = rollout(ref, t_contact=demo.t_contact, scene=scene)
    b = rollout(ref, t_contact=demo.t_contact, scene=scene)
    np.testing.assert_array_equal(a.hinge, b.hinge)
    np.testing.assert_array_equal(a.force, b.force)


@pytest.mark.slow
def test_contact_point_is_where_the_fingers_touch_the_handle(scene, demo):
    kin = Kinematics(scene)
    pads, bar = set(scene.tip_geoms), set(scene.handle_geoms)
    gaps = []

    def check(k, data):
        if k % 50 or not 1.8 <= k * 0.002 <= 2.4:  # grasped, pressing the handle
            return
        touching = [c.pos.copy() for c in data.contact[:data.ncon]
                    if {int(c.geom[0]), int(c.geom[1])} & pads and {int(c.geom[0]), int(c.geom[1])} & bar]
        assert len(touching) >= 2, "both pads should touch the bar"
        q = np.concatenate([data.qpos[scene.arm_qpos], [0.0]])
        q[7] = kin_width(data)
        gaps.append(np.linalg.norm(np.mean(touching, axis=0) - kin.contact_point(q)))

    def kin_width(data):
        from corl.tasks.door.scene import width_of_angle
        return float(width_of_angle(data.qpos[scene.finger_qpos]))

    _simulate(scene, demo.reference(), 2.4, on_step=check)
    assert len(gaps) >= 5
    assert max(gaps) < 0.008


def test_contact_point_jacobian_matches_finite_differences(scene, demo):
    kin = Kinematics(scene)
    q = demo.knots[5].copy()
    _, jac = kin.contact_point_jacobian(q)
    eps = 1e-6
    fd = np.empty((3, 8))
    for j in range(8):
        dq = np.zeros(8)
        dq[j] = eps
        fd[:, j] = (kin.contact_point(q + dq) - kin.contact_point(q - dq)) / (2 * eps)
    np.testing.assert_allclose(jac, fd, atol=1e-6)
    assert np.abs(jac[:, 7]).max() > 0.05  # the pads move along the approach as they open


def test_ik_reaches_the_handle(scene, demo):
    kin = Kinematics(scene)
    target = scene.handle_point(0.08)
    q = kin.ik(target, None, demo.knots[2])
    np.testing.assert_allclose(kin.contact_point(q), target, atol=1e-4)
    assert np.all(q[:7] >= scene.joint_lower - 1e-9) and np.all(q[:7] <= scene.joint_upper + 1e-9)
