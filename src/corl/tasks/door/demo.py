"""A scripted demonstration of opening the door, and its re-targeting to a new contact theta.

Glossary
--------
theta      (2,) the black-box parameters of Sec. VIII-B: (finger position along the handle
           relative to the demonstration's, m; finger opening width, m)
knots      (K, 8) joint-space waypoints q = (7 arm angles, gripper width) solved by IK
times      (K,) their times (s); the reference is piecewise linear between them, so it is
           deliberately jerky (the analytic cost J has something to improve)
t_contact  time the fingers close on the handle (the t_c of Eq. 6)

The demonstration: approach in front of the handle with the gripper open, move in, close on the
bar near the pivot (a poor contact, so the return has room to improve), press the handle past the
latch angle, then pull the door open along the hinge arc while holding the handle, and hold.
The handle is pressed before any pull: pulling a latched door open-loop makes it slam once the
latch lets go.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from corl.errors import InputError
from corl.mujoco import Target, piecewise_linear, solve_ik, solve_waypoints
from corl.tasks.door.kinematics import Kinematics
from corl.tasks.door.scene import DoorScene, load_scene

__all__ = ["DoorDemonstration", "scripted_demonstration", "shifted_reference", "grasp_rotation",
           "demonstration_waypoints", "DEMO_GRASP_R", "DEMO_WIDTH", "DEMO_DURATION", "CONTROL_DT"]

CONTROL_DT = 0.002
DEMO_DURATION = 5.0      # s
DEMO_GRASP_R = 0.035     # m from the pivot: close to it, so pressing needs much force
DEMO_WIDTH = 0.016       # m: 6 mm tighter than the 22 mm bar, a firm squeeze
OPEN_WIDTH = 0.04        # m, the approach width (the door-side tip clears the door)
PRESS_ANGLE = 0.55       # rad, past the 0.4 rad latch
OPEN_ANGLE = 0.42        # rad, door angle the reference pulls to
APPROACH_BACKOFF = 0.06  # m above the bar along the approach axis
# Posture that keeps the elbow off its limit in front of the door; the IK starts here.
_SEED = np.array([-0.3, 0.0, -1.0, -1.2, 0.0, -1.0, 0.0, OPEN_WIDTH])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


# Palm frame at the grasp with the door shut: approach straight down onto the bar, fingers open
# along x (one on the door side of the bar, one on the robot side). Pressing the handle down then
# relies on the pads' friction (so on the grip), and pulling the door on the robot-side pad. A
# vertical pinch from the front would turn the handle by twisting the wrist instead, and the lever
# arm would not matter.
_GRASP_R0 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])


def grasp_rotation(phi: float, alpha: float, yaw: float = 0.0) -> np.ndarray:
    """Palm orientation (3, 3) that holds the bar with the door at ``phi`` and handle at ``alpha``,
    the door turned by ``yaw`` about the vertical (``DoorGeometry.yaw``; both turn about z)."""
    return _rot_z(phi + yaw) @ _rot_x(alpha) @ _GRASP_R0


@dataclass(frozen=True)
class Waypoint:
    """A task-space waypoint: contact point at distance ``r`` along the lever, ``backoff`` metres
    in front of the bar along the approach axis, door ``phi``, handle ``alpha``, gripper ``width``."""

    time: float
    r: float
    phi: float
    alpha: float
    width: float
    backoff: float = 0.0
    offset: tuple = (0.0, 0.0, 0.0)  # extra world offset (m), for the start pose
    contact: bool = False     # part of the contact phase (re-solved when theta changes)


@dataclass(frozen=True)
class DoorDemonstration:
    """Waypoints, their IK solutions and the dense reference.

    Attributes
    ----------
    waypoints : tuple of Waypoint
    times : (K,) s
    knots : (K, 8) joint-space solutions
    t_contact : float, s
    theta : (2,) the contact parameters this reference realises
    duration : float, s
    start_fixed : the first knot is a given start configuration (the robot's rest posture), not
        the IK solution of the first waypoint
    """

    waypoints: tuple
    times: np.ndarray
    knots: np.ndarray
    t_contact: float
    theta: np.ndarray
    duration: float = DEMO_DURATION
    start_fixed: bool = False

    def reference(self, dt: float = CONTROL_DT) -> np.ndarray:
        """Dense reference (N, 8) at ``dt``, piecewise linear between the knots, N = duration/dt + 1."""
        return piecewise_linear(self.times, self.knots, self.duration, dt)


def _target(scene: DoorScene, wp: Waypoint) -> Target:
    """Contact point on the bar (backed off along the approach, offset in the door's frame), palm
    square to it, width."""
    rot = grasp_rotation(wp.phi, wp.alpha, scene.geometry.yaw)
    target = scene.handle_point(wp.r, wp.phi, wp.alpha) - wp.backoff * rot[:, 0]
    return Target(target + scene.door_vector(wp.offset), rot, gripper=wp.width)


def _solve(kin: Kinematics, wp: Waypoint, q_seed: np.ndarray) -> np.ndarray:
    return solve_ik(kin, kin.pads, _target(kin.scene, wp), q_seed, rotation_frame=kin.hand)


def demonstration_waypoints(r: float = DEMO_GRASP_R, width: float = DEMO_WIDTH) -> list[Waypoint]:
    """The demonstration's plan relative to the door (the same in every scene): grasp at ``r`` from
    the pivot, close to ``width``, press, pull, hold; the first waypoint is the start pose."""
    return _waypoints(r, width)


def _waypoints(r: float, width: float) -> list[Waypoint]:
    wps = [
        Waypoint(0.0, r, 0.0, 0.0, OPEN_WIDTH, backoff=0.10, offset=(-0.10, -0.05, 0.0)),
        Waypoint(0.7, r, 0.0, 0.0, OPEN_WIDTH, backoff=APPROACH_BACKOFF),
        Waypoint(1.3, r, 0.0, 0.0, OPEN_WIDTH, contact=True),
        Waypoint(1.7, r, 0.0, 0.0, width, contact=True),
    ]
    for i, alpha in enumerate(np.linspace(0.0, PRESS_ANGLE, 4)[1:]):
        wps.append(Waypoint(1.9 + 0.3 * i, r, 0.0, float(alpha), width, contact=True))
    pulls = np.linspace(0.0, OPEN_ANGLE, 7)[1:]
    for i, phi in enumerate(pulls):
        wps.append(Waypoint(2.6 + 1.6 * (i + 1) / len(pulls), r, float(phi), PRESS_ANGLE, width,
                            contact=True))
    wps.append(Waypoint(5.0, r, OPEN_ANGLE, PRESS_ANGLE, width, contact=True))
    return wps


def scripted_demonstration(scene: DoorScene | None = None, *, r: float = DEMO_GRASP_R,
                           width: float = DEMO_WIDTH, start=None) -> DoorDemonstration:
    """The scripted demonstration: IK waypoints joined piecewise-linearly (successful, jerky).

    ``start`` (8,): the configuration to start from (e.g. the rest posture of the unmoved scene's
    demonstration, for a moved door); None: the IK solution of the first waypoint.
    """
    kin = Kinematics(scene or load_scene())
    wps = _waypoints(r, width)
    grasp = next(i for i, wp in enumerate(wps) if wp.contact)
    first = 0 if start is None else 1
    # Walk outwards from the grasp so neighbouring knots stay on one IK branch.
    knots = solve_waypoints(kin, kin.pads, [_target(kin.scene, wp) for wp in wps[first:]], _SEED,
                            start=grasp - first, rotation_frame=kin.hand)
    if start is not None:
        knots = np.vstack([kin.robot.check_q(start), knots])
    closed = next(wp for wp in wps if wp.contact and wp.width == width)
    return DoorDemonstration(waypoints=tuple(wps), times=np.array([wp.time for wp in wps]),
                             knots=knots, t_contact=closed.time,
                             theta=np.array([r - DEMO_GRASP_R, width]), start_fixed=start is not None)


def shifted_reference(demo: DoorDemonstration, theta, scene: DoorScene | None = None,
                      *, steps: int = 4) -> DoorDemonstration:
    """Realise ``theta`` = (grasp shift along the lever, m; finger opening width, m).

    Every waypoint is re-solved by IK with the grasp moved ``theta[0]`` along the lever (towards
    its tip for positive values) and, from the closing knot on, the gripper width set to
    ``theta[1]``. The IK walks from the demonstration's knots in ``steps`` increments of the shift
    so the solutions stay on the demonstration's branch. This is a crude stand-in for the
    projection of Eq. 18, which goes through the B-spline and the motion optimizer.
    """
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (2,):
        raise InputError(f"theta has shape {theta.shape}, expected (2,) for the door task "
                         "(shift along the handle, finger width)")
    kin = Kinematics(scene or load_scene())
    base_r = demo.waypoints[0].r
    demo_width = demo.theta[1]
    knots = demo.knots.copy()
    new_wps = []
    for k, wp in enumerate(demo.waypoints):
        width = theta[1] if (wp.width == demo_width and wp.contact) else wp.width
        if k == 0 and demo.start_fixed:  # the rest posture does not move with the grasp
            new_wps.append(wp)
            continue
        q = knots[k]
        for frac in np.linspace(0.0, 1.0, steps + 1)[1:]:
            step_wp = replace(wp, r=base_r + frac * theta[0], width=width)
            q = _solve(kin, step_wp, q)
        knots[k] = q
        new_wps.append(replace(wp, r=base_r + theta[0], width=width))
    return DoorDemonstration(waypoints=tuple(new_wps), times=demo.times.copy(), knots=knots,
                             t_contact=demo.t_contact,
                             theta=np.array([demo.theta[0] + theta[0], theta[1]]),
                             duration=demo.duration, start_fixed=demo.start_fixed)
