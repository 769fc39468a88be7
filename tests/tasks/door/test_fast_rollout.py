"""The door's rollout equals a straightforward loop over mj_step, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from corl.mujoco import remove_static_load  # noqa: E402
from corl.tasks.door.controller import PDController, dense_reference  # noqa: E402
from corl.tasks.door.demo import shifted_reference  # noqa: E402
from corl.tasks.door.sim import HOLD_DISTANCE, _bar_distance, rollout  # noqa: E402


def plain_rollout(scene, reference, t_contact, duration: float = 5.0) -> dict:
    """The trial written out: set-points, compensation and mj_step each step, the latch checked
    each step, the grip (a loop over the contacts, the scalar bar distance) every 5th step."""
    model, data = scene.model, mujoco.MjData(scene.model)
    dt = model.opt.timestep
    ctrl = PDController(scene)
    q_ref, dq_ref = dense_reference(reference, duration, dt)
    u = ctrl.setpoints(q_ref, dq_ref)
    dofs = scene.robot.dofs
    ctrl.initialise(data, q_ref[0])
    data.eq_active[scene.latch_eq] = 1
    data.ctrl[:] = u[0]
    mujoco.mj_forward(model, data)
    data.qfrc_applied[dofs] = data.qfrc_bias[dofs]
    mujoco.mj_forward(model, data)
    pads, bar = set(scene.tip_geoms), set(scene.handle_geoms)
    log = {"hinge": [], "handle": [], "force_raw": [], "rot": [], "grip_t": [], "grip_d": [], "touch": []}
    t_release = np.nan
    for k in range(len(u)):
        if k > 0:
            data.ctrl[:] = u[k]
            data.qfrc_applied[dofs] = data.qfrc_bias[dofs]
            mujoco.mj_step(model, data)
            if np.isnan(t_release) and data.qpos[scene.handle_qpos] > scene.geometry.latch_angle:
                data.eq_active[scene.latch_eq] = 0
                t_release = k * dt
        log["hinge"].append(data.qpos[scene.hinge_qpos])
        log["handle"].append(data.qpos[scene.handle_qpos])
        log["force_raw"].append(data.sensordata[scene.force_adr:scene.force_adr + 3].copy())
        log["rot"].append(data.site_xmat[scene.ft_site].reshape(3, 3).copy())
        if k % 5 == 0:
            log["grip_t"].append(k * dt)
            log["touch"].append(any((g1 in pads and g2 in bar) or (g2 in pads and g1 in bar)
                                    for g1, g2 in data.contact.geom[:data.ncon].tolist()))
            log["grip_d"].append(_bar_distance(scene, data, data.site_xpos[scene.pad_sites].mean(axis=0)))
    out = {key: np.array(value) for key, value in log.items()}
    force = np.linalg.norm(remove_static_load(out["force_raw"], out["rot"], scene.hand_mass, model.opt.gravity), axis=1)
    window, after = np.arange(len(u)) * dt >= t_contact, out["grip_t"] >= t_contact
    return {**out, "force": force, "t_release": t_release, "held": bool(np.all(out["grip_d"][after] < HOLD_DISTANCE)),
            "force_mean": float(force[window].mean()), "force_max": float(force[window].max()),
            "pad_contact_fraction": float(out["touch"][after].mean()),
            "first_touch": out["grip_t"][out["touch"]][0] if out["touch"].any() else np.nan}


@pytest.mark.parametrize("theta", [None, [0.03, 0.014], [-0.02, 0.010], [0.12, 0.028]])
def test_rollout_equals_the_plain_loop(scene, demo, theta):
    ref = demo if theta is None else shifted_reference(demo, theta, scene)
    fast = rollout(ref.reference(), t_contact=ref.t_contact, scene=scene)
    plain = plain_rollout(scene, ref.reference(), ref.t_contact)
    for name, mine in (("hinge", fast.hinge), ("handle", fast.handle), ("force", fast.force),
                       ("grip_t", fast.grip_times), ("grip_d", fast.grip_distance),
                       ("force_raw", fast.info["force_raw"])):
        assert np.array_equal(mine, plain[name]), name
    for name in ("held", "force_mean", "force_max", "pad_contact_fraction"):
        assert getattr(fast, name) == plain[name], name
    assert np.array_equal(fast.t_release, plain["t_release"], equal_nan=True)
    assert np.array_equal(fast.info["first_touch"], plain["first_touch"], equal_nan=True)
    if theta is None:
        assert fast.success and not np.isnan(fast.t_release)  # the latch switch is exercised


def test_on_frame_sees_every_frame_and_data_is_reused(scene, demo):
    data = mujoco.MjData(scene.model)
    times = []
    first = rollout(demo.reference(), duration=0.5, scene=scene, data=data, frame_every=20,
                    on_frame=lambda t, d: times.append((t, d is data)))
    assert [t for t, _ in times] == [k * scene.model.opt.timestep for k in range(0, 251, 20)]
    assert all(same for _, same in times)
    again = rollout(demo.reference(), duration=0.5, scene=scene, data=data)  # reset, not carried over
    assert np.array_equal(first.hinge, again.hinge) and np.array_equal(first.grip_distance, again.grip_distance)


def test_bar_distances_equal_the_scalar_form_off_and_on_the_bar(scene):
    """Random handle poses and pad positions, the clip active at both ends of the lever."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from corl.tasks.door.sim import _bar_distances

    rng = np.random.default_rng(1)
    m, body = 400, scene.handle_body
    rot = Rotation.random(m, random_state=rng).as_matrix().reshape(m, 9)
    origin = rng.normal(scale=0.5, size=(m, 3))
    pads = origin[:, None, :] + rng.normal(scale=0.2, size=(m, 2, 3))
    fast = _bar_distances(scene, pads, rot, origin)
    plain = []
    for r, o, p in zip(rot, origin, pads):
        xmat, xpos = np.zeros((body + 1, 9)), np.zeros((body + 1, 3))
        xmat[body], xpos[body] = r, o
        plain.append(_bar_distance(scene, SimpleNamespace(xmat=xmat, xpos=xpos), p.mean(axis=0)))
    assert np.array_equal(fast, plain)
    local_y = np.einsum("kji,kj->ki", rot.reshape(m, 3, 3), pads.mean(axis=1) - origin)[:, 1]
    assert (-local_y < 0).any() and (-local_y > scene.geometry.lever_length).any()  # both clips taken
