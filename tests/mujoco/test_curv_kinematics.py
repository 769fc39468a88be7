"""Exact second derivatives of the kit's features against central differences of their Jacobians,
on the tiny arm of conftest (hinges, slide fingers, a nonlinear gripper), the PR2 of the door and
the Panda of example-robot-data.

Tolerances are relative to the scale of the Hessian (its largest entry): a central difference of
the exact Jacobian with step h errs by ``h^2 |y''''| + eps |dy/dq| / h``, about 1e-10 of the scale
at h = 1e-5.
"""

import sys
from pathlib import Path

import numpy as np
import pytest

from corl.mujoco import Gripper, Kinematics, Robot, load_spec
from corl.mujoco.features import Feature, coordinate_feature, orientation_feature, position_feature, stack
from corl.mujoco.kinematics import cross_table, point_hessian

ROOT = Path(__file__).resolve().parents[2]
Q0 = np.array([0.4, -0.7, 0.9, 0.03])
STEP = 1e-5


def hessian_by_differences(fk, q, step=STEP):
    """(d, Q, Q): ``[:, i, j] = d(dy/dq_j)/dq_i`` by central differences of fk's Jacobian."""
    cols = [(fk(q + step * e)[1] - fk(q - step * e)[1]) / (2 * step) for e in np.eye(len(q))]
    return np.stack(cols, axis=1)


def relative_error(H, fd):
    return float(np.abs(H - fd).max() / max(np.abs(fd).max(), 1e-300))


def expm(v):
    from corl.mujoco import skew

    t = np.linalg.norm(v)
    K = skew(v / t) if t > 0 else np.zeros((3, 3))
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


@pytest.fixture(scope="module")
def curved_arm(tiny):
    """The tiny arm with a nonlinear gripper: ``c = 0.1 (exp(10 a) - 1)``, so ``a''(c) != 0``."""
    spec = load_spec(tiny.xml, moving=tiny.joints + ("fl", "fr"))
    gripper = Gripper(("fl", "fr"), angle_of=lambda c: np.log1p(10.0 * np.asarray(c)) / 10.0,
                      slope=lambda a: np.exp(10.0 * np.asarray(a)), lower=0.0, upper=0.08)
    return Robot.from_spec(spec, tiny.joints, gripper)


def test_cross_table():
    rng = np.random.default_rng(0)
    u, v = rng.normal(size=(2, 3, 5)), rng.normal(size=(2, 3, 4))
    ref = np.cross(u[:, :, :, None], v[:, :, None, :], axis=1)
    np.testing.assert_allclose(cross_table(u, v), ref, rtol=1e-12, atol=1e-14 * np.abs(ref).max())


@pytest.mark.parametrize("robot", ["arm", "curved_arm"])
@pytest.mark.parametrize("frame", [("site", ("tool",)), ("site", ("tip_l",)), ("site", ("tip_l", "tip_r")),
                                   ("body", ("hand",)), ("body", ("l2",))])
def test_position_hessian_matches_differences(request, robot, frame):
    kin = Kinematics(request.getfixturevalue(robot))
    f = kin.site(*frame[1]) if frame[0] == "site" else kin.body(frame[1][0])
    fk = position_feature(kin, f)
    for q in (Q0, Q0 + np.array([-1.1, 0.8, 2.0, 0.02])):
        H = fk.hessian(q)
        assert H.shape == (3, 4, 4)
        np.testing.assert_array_equal(H, np.swapaxes(H, 1, 2))
        assert relative_error(H, hessian_by_differences(fk, q)) < 1e-8
        p, J, H2 = kin.position_hessian(q, f)
        np.testing.assert_array_equal(H2, H)
        np.testing.assert_array_equal(J, kin.position_jacobian(q, f)[1])


def test_gripper_curvature_term(curved_arm):
    """A finger tip slides by a(c) along a unit axis, so ``|d2p/dc2| = |a''(c)| = 10 / (1 + 10 c)^2``."""
    kin = Kinematics(curved_arm)
    H = position_feature(kin, kin.site("tip_l")).hessian(Q0)
    c = Q0[3]
    a2 = -10.0 / (1.0 + 10.0 * c) ** 2  # a''(c) of a = log(1 + 10 c) / 10
    assert np.linalg.norm(H[:, 3, 3]) == pytest.approx(abs(a2), rel=1e-6)


@pytest.mark.parametrize("robot", ["arm", "curved_arm"])
@pytest.mark.parametrize("frame", [("site", ("tool",)), ("site", ("tip_r",)), ("body", ("hand",))])
def test_angular_jacobian_derivative_matches_differences(request, robot, frame):
    """``W[:, i, j] = dJw[:, j]/dq_i``: not symmetric (a later joint does not move an earlier axis)."""
    kin = Kinematics(request.getfixturevalue(robot))
    f = kin.site(*frame[1]) if frame[0] == "site" else kin.body(frame[1][0])
    R, jw, W = kin.rotation_jacobian_derivative(Q0, f)
    np.testing.assert_array_equal(jw, kin.rotation_jacobian(Q0, f)[1])
    fd = hessian_by_differences(lambda q: kin.rotation_jacobian(q, f), Q0)
    assert relative_error(W, fd) < 1e-8


def test_point_hessian_of_slides_is_zero():
    """Two slides in a row (a translation): no curvature at all; a hinge after them: only its own."""
    jacp = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    jacr = np.zeros((3, 3))
    assert np.all(point_hessian(jacp, jacr, np.arange(3)) == 0.0)


@pytest.mark.parametrize("distance", [0.0, 0.1, 0.5, 2.0])
def test_orientation_hessian_exact(arm, distance):
    kin = Kinematics(arm)
    f = kin.site("tool")
    target = expm(np.array([0.3, -0.2, 0.4]) / np.linalg.norm([0.3, -0.2, 0.4]) * distance) @ kin.rotation(Q0, f)
    fk = orientation_feature(kin, f, target, weight=0.3)
    H = fk.hessian(Q0)
    fd = hessian_by_differences(fk, Q0)
    np.testing.assert_allclose(H, np.swapaxes(H, 1, 2), atol=1e-13 * np.abs(H).max())
    assert relative_error(H, fd) < 1e-8


@pytest.mark.parametrize("distance", [0.0, 0.5])
def test_orientation_small_angle_model(arm, distance):
    """exact=False: the symmetric part of the derivative of its Jacobian ``weight Jw`` - the exact
    Hessian at the target, a model away from it."""
    kin = Kinematics(arm)
    f = kin.body("hand")
    target = expm(np.array([0.3, -0.2, 0.4]) * distance) @ kin.rotation(Q0, f)
    small = orientation_feature(kin, f, target, weight=0.3, exact=False)
    fd = hessian_by_differences(small, Q0)
    assert relative_error(small.hessian(Q0), 0.5 * (fd + np.swapaxes(fd, 1, 2))) < 1e-8
    exact = orientation_feature(kin, f, target, weight=0.3).hessian(Q0)
    gap = np.abs(small.hessian(Q0) - exact).max()
    assert gap < 1e-10 * np.abs(exact).max() if distance == 0.0 else gap > 1e-3


def test_stack_and_cache(arm):
    kin = Kinematics(arm)
    parts = (position_feature(kin, kin.site("tip_l")), orientation_feature(kin, kin.body("hand"), np.eye(3)),
             coordinate_feature(4, 3))
    fk = stack(*parts)
    assert isinstance(fk, Feature) and fk.dim == 7
    y, J, H = fk.derivatives(Q0)
    assert y.shape == (7,) and J.shape == (7, 4) and H.shape == (7, 4, 4)
    np.testing.assert_array_equal(H, np.concatenate([p.hessian(Q0) for p in parts]))
    assert np.all(H[6] == 0.0)
    assert relative_error(H, hessian_by_differences(fk, Q0)) < 1e-8
    # the cache returns copies: a caller's edit does not reach it
    y[:] = np.nan
    H[:] = np.nan
    assert np.isfinite(fk(Q0)[0]).all() and np.isfinite(fk.hessian(Q0)).all()
    # a stack with a plain callable has no second derivatives
    plain = stack(parts[0], lambda q: (q[:1], np.eye(1, 4)))
    assert not hasattr(plain, "hessian")
    np.testing.assert_array_equal(plain(Q0)[1][:3], J[:3])


def test_feature_values_do_not_depend_on_the_cache(arm):
    """Interleaved configurations (more than one contact time): each value is that of its own q."""
    kin = Kinematics(arm)
    fk = position_feature(kin, kin.site("tool"))
    qs = [Q0 + 0.1 * k for k in range(5)]
    first = [fk(q)[0] for q in qs]
    fresh = position_feature(kin, kin.site("tool"))
    for q, y in zip(reversed(qs), reversed(first)):
        np.testing.assert_array_equal(fk(q)[0], y)
        np.testing.assert_array_equal(fresh(q)[0], y)


# ------------------------------------------------------------------------- the PR2 of the door
@pytest.fixture(scope="module")
def door():
    from corl.tasks.door.task import DoorTask

    return DoorTask()


def door_configurations(door):
    w = door.demonstration().w
    return door.spline.positions(w, door.contact_times[[0, 4, 9]])


def test_pr2_arm_hessians(door):
    """The PR2's arm block (7 x 7) is exact; the width's row and column meet the door's gripper
    table: ``angle_of_width`` interpolates a 2001-point table, so the finger angle is piecewise
    linear in c while the Jacobian takes its slope from the smooth ``dwidth_dangle`` - the two
    differ by ~1e-5 of the scale, which is what a difference quotient sees."""
    kin = door.kin
    wp = door.contacts[5]
    features = {"contact point": position_feature(kin, kin.pads), "hand": position_feature(kin, kin.hand),
                "palm, exact": orientation_feature(kin, kin.hand, door._grasp_rotation(wp), weight=0.3)}
    for q in door_configurations(door):
        for name, fk in features.items():
            H, fd = fk.hessian(q), hessian_by_differences(fk, q)
            assert relative_error(H[:, :7, :7], fd[:, :7, :7]) < 1e-7, name
            assert relative_error(H, fd) < 1e-4, name


def test_pr2_width_with_a_smooth_gripper(door):
    """With the width table's interpolation replaced by Newton's inverse of ``width_of_angle``, the
    width's row and column are as exact as the arm's (the chain rule through the PR2's four coupled
    finger joints and the curvature of their angle a(c))."""
    import dataclasses

    from corl.tasks.door.scene import angle_of_width, dwidth_dangle, width_of_angle

    def smooth_angle(c):
        a = float(angle_of_width(c))
        for _ in range(5):
            a -= (float(width_of_angle(a)) - float(c)) / float(dwidth_dangle(a))
        return a

    robot = door.kin.robot
    kin = Kinematics(dataclasses.replace(robot, gripper=dataclasses.replace(robot.gripper, angle_of=smooth_angle)))
    fk = position_feature(kin, kin.site("pad_l", "pad_r"))
    for q in door_configurations(door):
        assert relative_error(fk.hessian(q), hessian_by_differences(fk, q, step=1e-6)) < 1e-8


def test_pr2_door_feature_is_the_symmetrised_jacobian_derivative(door):
    """The door's own stacked feature (small-angle palm rows): its Hessian is what the forward
    differences of ``TaskSpaceFeature`` approximated before (their symmetric part)."""
    wp = door.contacts[5]
    fk = door._fk(wp, door.demonstration().theta)
    for q in door_configurations(door):
        H = fk.hessian(q)
        fd = hessian_by_differences(fk, q, step=1e-4)  # a step over several cells of the width table
        assert relative_error(H, 0.5 * (fd + np.swapaxes(fd, 1, 2))) < 1e-6


# ------------------------------------------------------------------------- the Panda example
def _panda_robot():
    try:
        from corl.errors import InputError
        from corl.mujoco import example_robot_dir

        example_robot_dir("panda_description")
    except (ImportError, InputError):
        pytest.skip("the Panda ships in example-robot-data 6.0.0")
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    from examples.panda_switch import build_robot

    return build_robot()


def test_panda_hessians():
    kin = Kinematics(_panda_robot())
    tips, hand = kin.site("panda_leftfinger_tip", "panda_rightfinger_tip"), kin.site("hand")
    q = np.array([0.1, 0.3, -0.2, -2.0, 0.1, 2.3, 0.6, 0.02])
    target = expm(np.array([0.2, -0.4, 0.1])) @ kin.rotation(q, hand)
    for fk in (position_feature(kin, tips), position_feature(kin, hand), orientation_feature(kin, hand, target, weight=0.3)):
        H = fk.hessian(q)
        assert relative_error(H, hessian_by_differences(fk, q)) < 1e-8
