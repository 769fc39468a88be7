"""Contexts of the door task (:class:`corl.problem.HasContexts`): where the door is, measured
before a trial and not chosen by the robot.

Glossary
--------
c        (4,) = (dz, dx, dy, yaw): the handle pivot raised by dz (m); the door face moved dx away
         from the robot (m, measured at the pivot); the door moved dy along the wall (m, +y: towards
         the robot's left); the door turned by yaw (rad) about the vertical axis through the handle
         pivot, counter-clockwise seen from above (positive turns the hinge side away from the
         robot). The pivot itself stays where dz, dx, dy put it, so the four act independently.
         c = 0 is the scene of the paper (:class:`corl.tasks.door.scene.DoorGeometry` defaults).
rest     the robot's start configuration, the same in every context: the first knot of the
         unmoved scene's scripted demonstration (the robot stands still while the door moves).
shift    where along the lever the scripted demonstration grasps, relative to the unmoved one's
         (theta[0]): the smallest of :data:`FALLBACK_SHIFTS` (0 first) from which the arm can follow
         the whole plan (IK) and the trial succeeds. A grasp further out keeps the hand away from the
         shoulder at the end of the pull and presses the handle past the latch with less force, which
         a low, far door yawed towards the robot needs.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from corl.errors import DemonstrationFailedError, InputError, NumericalError
from corl.problem import Bounds, check_theta
from corl.tasks.door.demo import CONTROL_DT, DEMO_GRASP_R, DoorDemonstration, scripted_demonstration
from corl.tasks.door.scene import DoorGeometry, DoorScene, load_scene

__all__ = ["CONTEXT_BOUNDS", "CONTEXT_LABELS", "CONTEXT_NAMES", "FALLBACK_SHIFTS", "check_context",
           "geometry_of_context", "rest_posture", "rest_start", "context_demonstration"]

CONTEXT_BOUNDS = Bounds(np.array([-0.05, -0.05, -0.05, -math.radians(10.0)]),
                        np.array([0.05, 0.05, 0.05, math.radians(10.0)]))
CONTEXT_LABELS = ("handle height dz (m)", "door distance dx (m)", "door position along the wall dy (m)",
                  "door yaw (rad)")
CONTEXT_NAMES = ("dz", "dx", "dy", "yaw")
FALLBACK_SHIFTS = tuple(round(0.01 * k, 2) for k in range(9))  # m along the lever: 0, 1 cm, ..., 8 cm


def check_context(c) -> np.ndarray:
    """``c`` as a (4,) float vector inside :data:`CONTEXT_BOUNDS`, or a one-line
    :class:`corl.errors.InputError` naming the coordinates outside the box and the box."""
    try:
        return check_theta(c, CONTEXT_BOUNDS, task="door", what="context")
    except InputError as error:
        arr = np.asarray(c, dtype=float) if np.ndim(c) == 1 and np.size(c) == CONTEXT_BOUNDS.dim else None
        if arr is None or not np.all(np.isfinite(arr)):
            raise
        lo, hi = CONTEXT_BOUNDS.lower, CONTEXT_BOUNDS.upper
        out = [f"{CONTEXT_NAMES[i]} = {arr[i]:.4g} is outside [{lo[i]:.4g}, {hi[i]:.4g}]"
               for i in range(arr.size) if not lo[i] <= arr[i] <= hi[i]]
        raise InputError(f"{'; '.join(out)}: {error}") from None


def geometry_of_context(c, base: DoorGeometry = DoorGeometry()) -> DoorGeometry:
    """The door of context ``c`` (4,): ``base`` with ``handle_height + dz``, ``door_distance + dx``,
    ``pivot_y + dy`` and ``yaw + yaw``; ``c = 0`` gives a geometry equal to ``base``."""
    dz, dx, dy, yaw = (float(v) for v in c)
    return replace(base, handle_height=base.handle_height + dz, door_distance=base.door_distance + dx,
                   pivot_y=base.pivot_y + dy, yaw=base.yaw + yaw)


@functools.lru_cache(maxsize=1)
def _unmoved_demonstration() -> DoorDemonstration:
    return scripted_demonstration(load_scene())


def rest_posture() -> np.ndarray:
    """The robot's start configuration (8,) in every context (a copy)."""
    return _unmoved_demonstration().knots[0].copy()


@functools.lru_cache(maxsize=8)
def _rest_start(num_control_points: int, duration: float) -> np.ndarray:
    from corl.trajectory.bspline import BSpline

    demo = _unmoved_demonstration()
    spline = BSpline(num_control_points, 8, duration=duration)
    t = np.arange(int(round(duration / CONTROL_DT)) + 1) * CONTROL_DT
    return spline.fit(t, demo.reference(CONTROL_DT))[:8]


def rest_start(num_control_points: int, duration: float) -> np.ndarray:
    """The first B-spline control point (8,) that every context's h holds fixed: that of the unmoved
    demonstration's fit (so w0 of ``DoorTask()`` starts there exactly)."""
    return _rest_start(int(num_control_points), float(duration)).copy()


def context_demonstration(scene: DoorScene, c=None, *, accept=None) -> DoorDemonstration:
    """The scripted demonstration in a moved scene, from the rest posture, grasping at the smallest
    shift of :data:`FALLBACK_SHIFTS` from which the arm can follow the whole plan and for which
    ``accept(demo)`` (e.g. "its rollout succeeds"; None: always) holds.

    Raises
    ------
    DemonstrationFailedError
        No shift up to 8 cm works: typically the pull ends too close to the shoulder (the PR2's
        elbow and shoulder lift at their limits). The context can still be tried by transfer (Eq. 18).
    """
    start = rest_posture()
    reasons = []
    for shift in FALLBACK_SHIFTS:
        try:
            demo = scripted_demonstration(scene, r=DEMO_GRASP_R + shift, start=start)
        except NumericalError:
            reasons.append("IK")
            continue
        if accept is None or accept(demo):
            return demo
        reasons.append("fails")
    where = "" if c is None else f" c = {np.array2string(np.asarray(c, dtype=float), precision=4)}"
    tried = ", ".join(f"{s:g} m: {r}" for s, r in zip(FALLBACK_SHIFTS, reasons))
    raise DemonstrationFailedError(f"no scripted door demonstration in context{where}: grasping further along the "
                                   f"lever did not help ({tried}; IK: the arm cannot reach the plan, fails: the "
                                   "trial fails)")
