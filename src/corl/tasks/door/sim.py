"""One door-opening trial in MuJoCo: track a reference, release the latch, measure the wrist force.

Glossary
--------
phi(t)        door hinge angle (rad), ``hinge``
alpha(t)      handle angle (rad), ``handle``
f(t)          interaction force at the wrist (N): the force-torque sensor's reading minus the
              static weight of the hand below it, rotated into the sensor frame
R             black-box return of Sec. VIII-B: minus the mean interaction force while the hand
              works the handle, divided by ``FORCE_SCALE`` (order 1, larger is better)
S             success: the door opened past ``OPEN_THRESHOLD`` and the hand kept hold of the
              handle from the grasp to the end

A rollout starts with the arm at rest on the reference's first configuration, the door shut and
latched. Each control step (500 Hz, the simulation step) sets the servo set-points, cancels the
arm's gravity and Coriolis forces, steps, and switches the latch equality off
(``data.eq_active``) once the handle is pressed past the latch angle. The latch stays released for
the rest of the trial.

The per-step hook decides only the latch (it changes the physics); otherwise it copies, through
views of ``data`` bound once, what the result needs: every step the joint angles and the wrist
sensor, every 5th step the pads, the handle pose and the contacts. The grip checks are worked out
from those copies after the trial, in one pass that gives the same floats as checking each step.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from corl.tasks.door.controller import PDController
from corl.tasks.door.scene import DoorScene, load_scene

__all__ = ["RolloutResult", "rollout", "OPEN_THRESHOLD", "FORCE_SCALE", "HOLD_DISTANCE"]

OPEN_THRESHOLD = 0.3   # rad, the door counts as open past this angle
FORCE_SCALE = 20.0     # N, divides the mean force into R
HOLD_DISTANCE = 0.02   # m, the contact point may stray this far from the bar's axis segment
_SAMPLE_EVERY = 5      # steps between grip checks (100 Hz)


@dataclass(frozen=True)
class RolloutResult:
    """What one trial measured.

    Attributes
    ----------
    times : (K,) s, the logged instants (every control step)
    hinge : (K,) rad, door angle
    handle : (K,) rad, handle angle
    force : (K,) N, interaction force magnitude at the wrist
    grip_distance : (M,) m, contact point to bar-axis-segment distance at the grip checks (100 Hz)
    grip_times : (M,) s
    t_contact : float, s, start of the interaction window (the grasp)
    t_release : float, s, latch release time (NaN if never released)
    held : bool, the contact point stayed within HOLD_DISTANCE of the bar from t_contact on
    pad_contact_fraction : float, share of grip checks after t_contact with a pad touching the bar
    force_mean, force_max : N, over the interaction window
    """

    times: np.ndarray
    hinge: np.ndarray
    handle: np.ndarray
    force: np.ndarray
    grip_times: np.ndarray
    grip_distance: np.ndarray
    t_contact: float
    t_release: float
    held: bool
    pad_contact_fraction: float
    force_mean: float
    force_max: float
    info: dict = field(default_factory=dict)

    @property
    def hinge_final(self) -> float:
        return float(self.hinge[-1])

    @property
    def handle_max(self) -> float:
        return float(self.handle.max())

    @property
    def success(self) -> bool:
        """S: the door opened past OPEN_THRESHOLD while the hand held the handle."""
        return bool(self.hinge_final > OPEN_THRESHOLD and self.held)

    @property
    def return_(self) -> float:
        """R: minus the mean interaction force over the window, in units of FORCE_SCALE."""
        return -self.force_mean / FORCE_SCALE

    def summary(self) -> dict:
        return {"success": self.success, "return": self.return_, "hinge_final": self.hinge_final,
                "handle_max": self.handle_max, "force_mean": self.force_mean,
                "force_max": self.force_max, "held": self.held, "t_release": self.t_release,
                "pad_contact_fraction": self.pad_contact_fraction}


def _bar_distance(scene: DoorScene, data, point: np.ndarray) -> float:
    """Distance (m) from ``point`` to the bar's axis segment, in the moving handle frame (the plain
    form of :func:`_bar_distances`, which rollouts use)."""
    g = scene.geometry
    body = scene.handle_body
    local = data.xmat[body].reshape(3, 3).T @ (point - data.xpos[body])
    along = np.clip(-local[1], 0.0, g.lever_length)
    return float(np.linalg.norm(local - np.array([-g.standoff, -along, 0.0])))


def _bar_distances(scene: DoorScene, pads: np.ndarray, rot: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """:func:`_bar_distance` of the pads' midpoints at M instants, bit for bit, in one pass.

    Parameters
    ----------
    pads : (M, 2, 3) the two pad sites' world positions.
    rot, origin : (M, 9), (M, 3) the handle body's ``xmat`` and ``xpos``.

    Returns
    -------
    (M,) m. Each instant takes the same floating point steps as :func:`_bar_distance`: a stacked
    ``matmul`` makes the same BLAS call per instant as ``(3, 3) @ (3,)`` (gemv on the same strides),
    a stacked ``(1, 3) @ (3, 1)`` the same dot as ``norm`` of a vector, and ``(a + b) / 2`` is
    ``mean`` of two rows.
    """
    g = scene.geometry
    point = (pads[:, 0] + pads[:, 1]) / 2
    local = np.matmul(rot.reshape(-1, 3, 3).transpose(0, 2, 1), (point - origin)[:, :, None])[:, :, 0]
    along = np.clip(-local[:, 1], 0.0, g.lever_length)
    d = local - np.stack([np.full_like(along, -g.standoff), -along, np.zeros_like(along)], axis=1)
    return np.sqrt(np.matmul(d[:, None, :], d[:, :, None])[:, 0, 0])


def _recorder(scene: DoorScene, data, n: int, on_frame, frame_every: int):
    """``(step, log)``: the per-step hook of :func:`rollout` for ``data``, and what it fills.

    ``log`` holds, at every step, ``qpos`` (n, nq), ``force_raw`` (n, 3), ``rot_ft`` (n, 9); at
    every ``_SAMPLE_EVERY``-th (M of them), ``sites`` (M, nsite, 3), ``handle_rot`` (M, 9),
    ``handle_pos`` (M, 3) and ``contacts``, a list of ``(j, data.contact.geom)`` of the checks with
    contacts; ``t_release`` (s, NaN until the latch lets go). The hook only copies, through views
    of ``data`` bound here (``mj_resetData`` keeps its buffers): the grip checks are worked out
    from the copies after the trial (:func:`_grip`). Only the latch is decided during the trial,
    every step, because releasing it changes the physics.
    """
    dt = scene.model.opt.timestep
    m = len(range(0, n, _SAMPLE_EVERY))
    body = scene.handle_body
    log = {"qpos": np.empty((n, scene.model.nq)), "force_raw": np.empty((n, 3)), "rot_ft": np.empty((n, 9)),
           "sites": np.empty((m,) + data.site_xpos.shape), "handle_rot": np.empty((m, 9)),
           "handle_pos": np.empty((m, 3)), "contacts": [], "t_release": np.nan}
    qpos_log, force_log, rot_log = log["qpos"], log["force_raw"], log["rot_ft"]
    sites_log, handle_rot_log, handle_pos_log = log["sites"], log["handle_rot"], log["handle_pos"]
    contacts = log["contacts"]
    qpos, eq_active, sites = data.qpos, data.eq_active, data.site_xpos
    force = data.sensordata[scene.force_adr:scene.force_adr + 3]
    rot, handle_rot, handle_pos = data.site_xmat[scene.ft_site], data.xmat[body], data.xpos[body]
    haq, latch, latch_angle = scene.handle_qpos, scene.latch_eq, scene.geometry.latch_angle
    released = False

    def step(k: int, _data) -> None:
        nonlocal released
        if not released and k > 0 and qpos[haq] > latch_angle:
            eq_active[latch] = 0  # the latch lets go, for the rest of the trial
            released, log["t_release"] = True, k * dt
        qpos_log[k] = qpos
        force_log[k] = force
        rot_log[k] = rot
        if on_frame is not None and k % frame_every == 0:
            on_frame(k * dt, data)
        if k % _SAMPLE_EVERY == 0:
            j = k // _SAMPLE_EVERY
            sites_log[j] = sites
            handle_rot_log[j] = handle_rot
            handle_pos_log[j] = handle_pos
            if data.ncon:
                contacts.append((j, data.contact.geom.copy()))

    return step, log


def _grip(scene: DoorScene, log: dict) -> tuple[np.ndarray, np.ndarray]:
    """The grip checks of a trial from its ``log`` (:func:`_recorder`): whether a pad touched the
    bar (M,) bool, and the pads' midpoint's distance to the bar's axis segment (M,) m."""
    from corl.mujoco.forces import ContactPairs

    touch = np.zeros(len(log["handle_pos"]), dtype=bool)
    if log["contacts"]:
        checks, geoms = zip(*log["contacts"])
        check = np.repeat(checks, [len(g) for g in geoms])
        pads_on_bar = ContactPairs(scene.model, scene.tip_geoms, scene.handle_geoms)
        touch[check[pads_on_bar.match(np.concatenate(geoms))]] = True
    distance = _bar_distances(scene, log["sites"][:, scene.pad_sites], log["handle_rot"], log["handle_pos"])
    return touch, distance


def rollout(reference, *, duration: float = 5.0, t_contact: float | None = None,
            scene: DoorScene | None = None, data=None, on_frame=None, frame_every: int = 20) -> RolloutResult:
    """Simulate one trial of tracking ``reference`` (:func:`corl.mujoco.track`).

    Parameters
    ----------
    reference : (N, 8) array at the 2 ms control step, or callable ``t -> (8,)``
    duration : s
    t_contact : s, start of the interaction window (force statistics and the grip check). None:
        the first instant a fingertip pad touches the handle.
    scene : DoorScene, defaults to :func:`load_scene`
    data : mujoco.MjData to reuse (it is reset), optional
    on_frame : callable ``(t, data) -> None`` called every ``frame_every`` steps (e.g. to render)

    Returns
    -------
    RolloutResult
    """
    import mujoco

    from corl.mujoco import remove_static_load, track

    scene = scene or load_scene()
    model = scene.model
    dt = model.opt.timestep
    n = int(round(duration / dt)) + 1
    data = mujoco.MjData(model) if data is None else data
    step, log = _recorder(scene, data, n, on_frame, frame_every)
    latch = scene.latch_eq

    def latch_on(data):
        data.eq_active[latch] = 1

    track(scene.robot, PDController(scene), reference, duration, data=data, prepare=latch_on, on_step=step)
    grip_touch, grip_d = _grip(scene, log)
    grip_t = np.arange(0, n, _SAMPLE_EVERY) * dt
    first_touch = grip_t[grip_touch][0] if grip_touch.any() else np.nan
    t_release = log["t_release"]

    times = np.arange(n) * dt
    hinge, handle = log["qpos"][:, scene.hinge_qpos].copy(), log["qpos"][:, scene.handle_qpos].copy()
    force_raw, rot_ft = log["force_raw"], log["rot_ft"].reshape(n, 3, 3)
    force = np.linalg.norm(remove_static_load(force_raw, rot_ft, scene.hand_mass, model.opt.gravity), axis=1)

    t_window = t_contact if t_contact is not None else first_touch
    if np.isnan(t_window):
        held, contact_fraction, f_mean, f_max = False, 0.0, 0.0, 0.0
        t_window = float("nan")
    else:
        in_window = times >= t_window
        after = grip_t >= t_window
        held = bool(np.all(grip_d[after] < HOLD_DISTANCE))
        contact_fraction = float(grip_touch[after].mean()) if after.any() else 0.0
        f_mean, f_max = float(force[in_window].mean()), float(force[in_window].max())
    return RolloutResult(times=times, hinge=hinge, handle=handle, force=force, grip_times=grip_t,
                         grip_distance=grip_d, t_contact=float(t_window), t_release=float(t_release),
                         held=held, pad_contact_fraction=contact_fraction, force_mean=f_mean,
                         force_max=f_max, info={"first_touch": float(first_touch),
                                                "force_raw": force_raw})
