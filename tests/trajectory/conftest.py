"""Shared fixtures of the trajectory tests: a small spatial 7-DoF arm with closed-form derivatives."""

from __future__ import annotations

import numpy as np
import pytest

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
