"""Inverse kinematics from task-space waypoints: damped least squares on the robot's joints.

Glossary
--------
Target     a waypoint: world position of a frame (3,), optionally its orientation (3, 3), and
           optionally the gripper coordinate to hold there
e          stacked residual ``[p_target - p; rot_weight * rotation_error(R_target, R)]`` (3 or 6,)
A          its Jacobian in the robot's joints (3 or 6, J); the gripper coordinate is not solved for
damping    lambda of the damped least-squares step ``dq = A^T (A A^T + lambda I)^{-1} e``

Each step is capped at ``max_step`` rad per joint and clipped to the joint limits (1e-4 inside).
:func:`solve_waypoints` walks a list of targets outward from one solved waypoint, each seeded with
its neighbour's solution, so that neighbouring knots stay on one IK branch.
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Real
from typing import Sequence

import numpy as np

from corl.errors import InputError, NumericalError
from corl.mujoco.kinematics import Frame, Kinematics, rotation_error

__all__ = ["Target", "solve_ik", "solve_waypoints"]


@dataclass(frozen=True)
class Target:
    """One task-space waypoint.

    Attributes
    ----------
    position : (3,) world position of the IK's point frame
    rotation : (3, 3) world orientation of its rotation frame, or None to leave it free
    gripper : gripper coordinate to hold, or None to keep the seed's
    """

    position: np.ndarray
    rotation: np.ndarray | None = None
    gripper: float | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.position, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise InputError(f"Target.position must be a finite (3,) point, got {self.position!r}")
        object.__setattr__(self, "position", p)
        if self.rotation is not None:
            r = np.asarray(self.rotation, dtype=float)
            if r.shape != (3, 3) or not np.allclose(r @ r.T, np.eye(3), atol=1e-6):
                raise InputError("Target.rotation must be a rotation matrix (3, 3) or None")
            object.__setattr__(self, "rotation", r)
        if self.gripper is not None and not (isinstance(self.gripper, Real) and np.isfinite(self.gripper)):
            raise InputError(f"Target.gripper must be a finite gripper coordinate or None, got {self.gripper!r}")


def solve_ik(kin: Kinematics, point: Frame, target: Target, q_init: np.ndarray, *,
             rotation_frame: Frame | None = None, rot_weight: float = 0.3, damping: float = 1e-3,
             iterations: int = 200, tol: float = 1e-5, max_step: float = 0.3,
             max_residual: float = 1e-3) -> np.ndarray:
    """Damped-least-squares IK: put ``point`` at ``target.position`` (and the orientation).

    Parameters
    ----------
    kin : Kinematics of the robot.
    point : the frame to place (a site, mean of sites, or body).
    target : Target; its ``gripper`` (if given) replaces q_init's gripper coordinate.
    q_init : (Q,) start.
    rotation_frame : frame whose orientation must match ``target.rotation``; default ``point``.
    rot_weight : metres per radian of orientation error in the stacked residual.
    tol : stop when the residual norm is below it (m).
    max_residual : raise when the final residual norm is above it (m).

    Returns
    -------
    q : (Q,) within the joint limits.

    Raises
    ------
    NumericalError : the residual stays above ``max_residual`` (out of reach, or a joint limit).
    """
    robot = kin.robot
    J = robot.num_joints
    q = robot.check_q(q_init).copy()
    if target.gripper is not None:
        if robot.gripper is None:
            raise InputError("Target.gripper is set but the robot has no gripper")
        q[J] = float(target.gripper)
    rot_frame = rotation_frame or point
    lo, hi = robot.lower[:J] + 1e-4, robot.upper[:J] - 1e-4
    q[:J] = np.clip(q[:J], lo, hi)
    e = np.full(3, np.inf)
    for _ in range(iterations):
        pos, jac = kin.position_jacobian(q, point)
        err = [target.position - pos]
        rows = [jac[:, :J]]
        if target.rotation is not None:
            rot, jw = kin.current_rotation_jacobian(rot_frame)
            err.append(rot_weight * rotation_error(target.rotation, rot))
            rows.append(rot_weight * jw[:, :J])
        e, a = np.concatenate(err), np.vstack(rows)
        if np.linalg.norm(e) < tol:
            break
        step = a.T @ np.linalg.solve(a @ a.T + damping * np.eye(a.shape[0]), e)
        step *= min(1.0, max_step / max(np.abs(step).max(), 1e-12))
        q[:J] = np.clip(q[:J] + step, lo, hi)
    if np.linalg.norm(e) > max_residual:
        raise NumericalError(f"IK did not reach the target at {np.round(target.position, 4).tolist()} "
                             f"(residual {np.linalg.norm(e):.4f} m); it may be out of reach or against a "
                             "joint limit: move the waypoint or start from another q_init")
    return q


def solve_waypoints(kin: Kinematics, point: Frame, targets: Sequence[Target], q_seed: np.ndarray, *,
                    start: int = 0, **options) -> np.ndarray:
    """IK of every target, walking outward from ``targets[start]`` (seeded with ``q_seed``).

    Parameters
    ----------
    targets : the waypoints, in time order.
    q_seed : (Q,) seed of the first solve; each later solve starts from its neighbour's solution.
    start : index solved first (e.g. the grasp, where the branch matters most).
    options : passed to :func:`solve_ik`.

    Returns
    -------
    knots : (K, Q) joint-space waypoints.
    """
    targets = list(targets)
    if not targets:
        raise InputError("solve_waypoints needs at least one target")
    if not 0 <= start < len(targets):
        raise InputError(f"start {start} is outside the {len(targets)} targets")
    knots: list = [None] * len(targets)
    knots[start] = solve_ik(kin, point, targets[start], q_seed, **options)
    for i in range(start + 1, len(targets)):
        knots[i] = solve_ik(kin, point, targets[i], knots[i - 1], **options)
    for i in range(start - 1, -1, -1):
        knots[i] = solve_ik(kin, point, targets[i], knots[i + 1], **options)
    return np.array(knots)
