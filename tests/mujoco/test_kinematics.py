"""FK, Jacobians and orientation features of the kit against finite differences."""

import numpy as np
import pytest

from corl.errors import InputError
from corl.mujoco import (Kinematics, coordinate_feature, orientation_feature, position_feature, rotation_error,
                         rotation_error_jacobian, skew, stack)

Q0 = np.array([0.4, -0.7, 0.9, 0.03])
STEP = 1e-6


def central_difference(f, q, step=STEP):
    """(d, Q) central differences of f: (Q,) -> (d,); error O(step^2)."""
    cols = [(np.asarray(f(q + step * e)) - np.asarray(f(q - step * e))) / (2 * step) for e in np.eye(len(q))]
    return np.array(cols).T


def expm(v):
    """Rodrigues: the rotation matrix exp([v]x)."""
    t = np.linalg.norm(v)
    K = skew(v / t) if t > 0 else np.zeros((3, 3))
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


@pytest.mark.parametrize("frame", [("site", ("tool",)), ("site", ("tip_l",)), ("site", ("tip_l", "tip_r")),
                                   ("body", ("hand",))])
def test_position_jacobian_matches_differences(arm, frame):
    kin = Kinematics(arm)
    f = kin.site(*frame[1]) if frame[0] == "site" else kin.body(frame[1][0])
    p, J = kin.position_jacobian(Q0, f)
    assert J.shape == (3, 4)
    fd = central_difference(lambda q: kin.position(q, f), Q0)
    # a 1e-6 step: truncation ~ step^2 |p'''| ~ 1e-12, rounding ~ eps |p| / step ~ 1e-10
    np.testing.assert_allclose(J, fd, atol=1e-8)
    if frame[1] == ("tip_l",):  # the gripper column: the finger slides c / 2 along its axis
        assert np.linalg.norm(J[:, 3]) == pytest.approx(0.5, rel=1e-9)
    if frame[1] == ("tip_l", "tip_r"):  # the midpoint of symmetric fingers ignores the width
        assert np.linalg.norm(J[:, 3]) < 1e-12


def test_rotation_jacobian_is_angular_velocity(arm):
    kin = Kinematics(arm)
    f = kin.site("tool")
    R, Jw = kin.rotation_jacobian(Q0, f)
    for j in range(4):
        e = np.eye(4)[j] * STEP
        dR = (kin.rotation(Q0 + e, f) - kin.rotation(Q0 - e, f)) / (2 * STEP)
        omega = dR @ R.T  # [omega]x = dR/dq R^T
        np.testing.assert_allclose([omega[2, 1], omega[0, 2], omega[1, 0]], Jw[:, j], atol=1e-8)


def test_rotation_error_inverts_exp():
    rng = np.random.default_rng(3)
    for _ in range(20):
        R = expm(rng.normal(size=3))
        v = rng.normal(size=3)
        v *= rng.uniform(0.01, 3.0) / np.linalg.norm(v)
        e = rotation_error(expm(v) @ R, R)
        np.testing.assert_allclose(e, v, atol=1e-9)
    assert np.allclose(rotation_error(np.eye(3), np.eye(3)), 0.0)


def test_rotation_error_jacobian_matches_differences():
    rng = np.random.default_rng(4)
    R_t = expm(rng.normal(size=3))
    for angle in (1e-8, 0.3, 2.0):
        v = rng.normal(size=3)
        R = expm(angle * v / np.linalg.norm(v)) @ R_t
        e = rotation_error(R_t, R)
        fd = central_difference(lambda w: -rotation_error(R_t, expm(w) @ R), np.zeros(3))
        np.testing.assert_allclose(rotation_error_jacobian(e), fd, atol=1e-7)


@pytest.mark.parametrize("distance", [0.0, 0.5])
def test_orientation_feature_matches_differences(arm, distance):
    kin = Kinematics(arm)
    f = kin.site("tool")
    R0 = kin.rotation(Q0, f)
    target = expm(np.array([0.3, -0.2, 0.4]) * distance) @ R0
    fk = orientation_feature(kin, f, target, weight=0.3)
    y, J = fk(Q0)
    assert np.linalg.norm(y) == pytest.approx(0.3 * np.linalg.norm([0.3, -0.2, 0.4]) * distance, abs=1e-12)
    fd = central_difference(lambda q: fk(q)[0], Q0)
    np.testing.assert_allclose(J, fd, atol=1e-8)
    # the small-angle Jacobian is exact at the target only
    _, J_small = orientation_feature(kin, f, target, weight=0.3, exact=False)(Q0)
    gap = np.abs(J_small - fd).max()
    assert gap < 1e-8 if distance == 0.0 else gap > 1e-3


def test_stacked_pose_feature(arm):
    kin = Kinematics(arm)
    tip = kin.site("tip_l")
    fk = stack(position_feature(kin, tip), orientation_feature(kin, kin.body("hand"), np.eye(3)), coordinate_feature(4, 3))
    y, J = fk(Q0)
    assert y.shape == (7,) and J.shape == (7, 4)
    assert y[6] == Q0[3]
    np.testing.assert_allclose(J, central_difference(lambda q: fk(q)[0], Q0), atol=1e-8)


def test_bad_input(arm):
    kin = Kinematics(arm)
    with pytest.raises(InputError, match=r"expected \(4,\) = 3 joints \+ gripper"):
        kin.position(np.zeros(3), kin.site("tool"))
    with pytest.raises(InputError, match="no site named 'nope'"):
        kin.site("nope")
    with pytest.raises(InputError, match="rotation matrix"):
        orientation_feature(kin, kin.site("tool"), np.ones((3, 3)))
