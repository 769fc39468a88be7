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
    """Distance (m) from ``point`` to the bar's axis segment, in the moving handle frame."""
    g = scene.geometry
    body = scene.handle_body
    local = data.xmat[body].reshape(3, 3).T @ (point - data.xpos[body])
    along = np.clip(-local[1], 0.0, g.lever_length)
    return float(np.linalg.norm(local - np.array([-g.standoff, -along, 0.0])))


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
    from corl.mujoco import remove_static_load, touching, track

    scene = scene or load_scene()
    model = scene.model
    dt = model.opt.timestep
    n = int(round(duration / dt)) + 1
    hinge, handle = np.empty(n), np.empty(n)
    force_raw = np.empty((n, 3))
    rot_ft = np.empty((n, 3, 3))
    grip_t, grip_d, grip_touch = [], [], []
    pads = np.array(scene.tip_geoms)
    bar = np.array(scene.handle_geoms)
    latch, latch_angle = scene.latch_eq, scene.geometry.latch_angle
    hq, haq, fa = scene.hinge_qpos, scene.handle_qpos, scene.force_adr
    site = scene.ft_site
    state = {"released": False, "t_release": np.nan, "first_touch": np.nan}

    def latch_on(data):
        data.eq_active[latch] = 1

    def step(k, data):
        if k > 0 and not state["released"] and data.qpos[haq] > latch_angle:
            data.eq_active[latch] = 0  # the latch lets go, for the rest of the trial
            state["released"], state["t_release"] = True, k * dt
        hinge[k] = data.qpos[hq]
        handle[k] = data.qpos[haq]
        force_raw[k] = data.sensordata[fa:fa + 3]
        rot_ft[k] = data.site_xmat[site].reshape(3, 3)
        if on_frame is not None and k % frame_every == 0:
            on_frame(k * dt, data)
        if k % _SAMPLE_EVERY == 0:
            touch = touching(data, pads, bar)
            if touch and np.isnan(state["first_touch"]):
                state["first_touch"] = k * dt
            grip_t.append(k * dt)
            grip_touch.append(touch)
            grip_d.append(_bar_distance(scene, data, data.site_xpos[scene.pad_sites].mean(axis=0)))

    track(scene.robot, PDController(scene), reference, duration, data=data, prepare=latch_on, on_step=step)
    t_release, first_touch = state["t_release"], state["first_touch"]

    times = np.arange(n) * dt
    force = np.linalg.norm(remove_static_load(force_raw, rot_ft, scene.hand_mass, model.opt.gravity), axis=1)

    t_window = t_contact if t_contact is not None else first_touch
    grip_t, grip_d, grip_touch = np.array(grip_t), np.array(grip_d), np.array(grip_touch)
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
