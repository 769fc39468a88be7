"""Eq. 6 features of a MuJoCo robot: ``q -> (y, dy/dq)`` callbacks for
:class:`corl.trajectory.TaskSpaceFeature`.

Glossary
--------
q       (Q,) task configuration
y       (d,) a task-space quantity whose target the constraint ``h = y(xi(w, t_k)) - target_k``
        holds at the contact times t_k (Eq. 6)
weight  metres per radian: scales an orientation error so it can share ``h`` with positions

Each builder returns a plain function ``fk(q) -> (y (d,), dy/dq (d, Q))``; :func:`stack` joins
several into one (the values concatenated, the Jacobians stacked), so one
``TaskSpaceFeature(spline, stack(...), [t_k], target_k)`` constrains a whole pose at t_k.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from corl.errors import InputError
from corl.mujoco.kinematics import Frame, Kinematics, rotation_error, rotation_error_jacobian

__all__ = ["position_feature", "orientation_feature", "coordinate_feature", "stack"]

FK = Callable[[np.ndarray], "tuple[np.ndarray, np.ndarray]"]


def position_feature(kin: Kinematics, frame: Frame) -> FK:
    """``q -> (p (3,), dp/dq (3, Q))``: the frame's world position (the contact point of Eq. 6)."""

    def fk(q):
        return kin.position_jacobian(q, frame)

    return fk


def orientation_feature(kin: Kinematics, frame: Frame, r_target: np.ndarray, *, weight: float = 1.0,
                        exact: bool = True) -> FK:
    """``q -> (y (3,), dy/dq (3, Q))`` with ``y = -weight * rotation_error(r_target, R(q))``.

    ``y`` is zero when the frame has the orientation ``r_target`` (3, 3), and ``|y| / weight`` is the
    angle to it. Its target in a :class:`~corl.trajectory.TaskSpaceFeature` is zeros(3).

    Parameters
    ----------
    exact : the exact Jacobian ``weight J_r^{-1}(e) Jw`` (:func:`rotation_error_jacobian`). False:
        the small-angle one, ``weight Jw``, exact at the target only (the classic resolved-rate
        Jacobian; Gauss-Newton still converges to ``y = 0``, more slowly far from it).
    """
    r_target = np.asarray(r_target, dtype=float)
    if r_target.shape != (3, 3) or not np.allclose(r_target @ r_target.T, np.eye(3), atol=1e-6):
        raise InputError(f"r_target must be a rotation matrix (3, 3), got shape {r_target.shape}")
    weight = float(weight)
    if not weight > 0:
        raise InputError(f"weight must be positive (metres per radian), got {weight}")

    def fk(q):
        rot, jw = kin.rotation_jacobian(q, frame)
        e = rotation_error(r_target, rot)
        jac = weight * jw if not exact else weight * (rotation_error_jacobian(e) @ jw)
        return -weight * e, jac

    return fk


def coordinate_feature(dim: int, index: int) -> FK:
    """``q -> (q[index] (1,), e_index (1, dim))``: one coordinate of q, e.g. the gripper's."""
    if not 0 <= index < dim:
        raise InputError(f"index {index} is outside q's {dim} coordinates")
    row = np.zeros((1, dim))
    row[0, index] = 1.0

    def fk(q):
        return np.asarray(q, dtype=float)[index : index + 1].copy(), row.copy()

    return fk


def stack(*features: FK) -> FK:
    """One ``fk`` from several: values concatenated (sum d,), Jacobians stacked (sum d, Q)."""
    if not features or not all(callable(f) for f in features):
        raise InputError("stack() needs one or more callables q -> (y, dy/dq)")

    def fk(q):
        parts = [f(q) for f in features]
        return np.concatenate([np.atleast_1d(y) for y, _ in parts]), np.vstack([np.atleast_2d(j) for _, j in parts])

    return fk
