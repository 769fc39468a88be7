"""Shared fixtures of the trajectory tests: a small spatial 7-DoF arm with closed-form derivatives,
and a reaching problem on it (B-spline, acceleration cost, start/goal and a contact point)."""

from __future__ import annotations

import numpy as np
import pytest

from corl.trajectory.bspline import BSpline
from corl.trajectory.features import (
    TaskSpaceFeature,
    TrajectoryProblem,
    acceleration_feature,
    configuration_feature,
)

AXES = "zyzyzyz"
LINKS = (0.33, 0.0, 0.40, 0.0, 0.39, 0.0, 0.13)


def _rot(axis: str, q: float) -> np.ndarray:
    c, s = np.cos(q), np.sin(q)
    if axis == "z":
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def arm_fk(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hand position (3,) and geometric Jacobian (3, 7) of a z/y-alternating revolute chain."""
    R, p = np.eye(3), np.zeros(3)
    origins, axes = [], []
    for qi, axis, length in zip(q, AXES, LINKS):
        origins.append(p)
        axes.append(R[:, 2] if axis == "z" else R[:, 1])
        R = R @ _rot(axis, qi)
        p = p + length * R[:, 2]
    return p, np.cross(np.array(axes), p - np.array(origins)).T


def arm_fk_hessian(q: np.ndarray) -> np.ndarray:
    """d^2 y / dq^2 (3, 7, 7): entry (i, j) = a_min(i,j) x J_max(i,j)."""
    R = np.eye(3)
    axes = []
    for qi, axis in zip(q, AXES):
        axes.append(R[:, 2] if axis == "z" else R[:, 1])
        R = R @ _rot(axis, qi)
    _, J = arm_fk(q)
    H = np.empty((3, 7, 7))
    for i in range(7):
        for j in range(7):
            H[:, i, j] = np.cross(axes[min(i, j)], J[:, max(i, j)])
    return H


@pytest.fixture
def arm():
    return arm_fk, arm_fk_hessian


def reaching_problem(fk, fk_hessian, P=14, offset=(0.04, -0.03, -0.06)):
    """Squared accelerations, start and goal fixed, the hand at a point at t_c = 0.45 T (n = 7 P).

    Returns (spline, problem, w0) with w0 a smooth fit that misses the contact point by ``offset``.
    """
    spline = BSpline(P, 7, duration=2.0)
    t = np.linspace(0.0, 2.0, 6 * P)
    demo = np.stack([0.4 * np.sin(t + j) + 0.1 * j for j in range(7)], axis=1)
    w0 = spline.fit(t, demo)
    target = fk(spline.positions(w0, [0.9])[0])[0] + np.asarray(offset)
    problem = TrajectoryProblem(
        spline.n,
        [acceleration_feature(spline, 2 * P)],
        [
            configuration_feature(spline, 0.0, demo[0]),
            configuration_feature(spline, 2.0, demo[-1]),
            TaskSpaceFeature(spline, fk, [0.9], target, fk_hessian=fk_hessian),
        ],
    )
    return spline, problem, w0


@pytest.fixture
def reaching(arm):
    """:func:`reaching_problem` on the 7-DoF arm: ``reaching(P=14, offset=...) -> (spline, problem, w0)``."""

    def build(P=14, offset=(0.04, -0.03, -0.06), fk_hessian=True):
        fk, hessian = arm
        return reaching_problem(fk, hessian if fk_hessian else None, P=P, offset=offset)

    return build
