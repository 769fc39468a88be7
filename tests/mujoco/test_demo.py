"""IK from task-space waypoints, the B-spline fit and the projection of the demonstration onto h = 0."""

import numpy as np
import pytest

from corl.errors import InputError, NumericalError
from corl.mujoco import (Kinematics, Target, fit_demonstration, orientation_feature, position_feature,
                         project_demonstration, solve_ik, solve_waypoints, stack)
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature

Q_SEED = np.array([0.2, -0.5, 0.1, 0.02])
IK_TOL = 1e-6  # m: the IK stops below 1e-7 of stacked residual; we ask for 10x that per waypoint


def waypoints(kin):
    """Four reachable targets around the arm's seed pose: positions from FK of known configurations."""
    qs = [Q_SEED + d for d in ([0, 0, 0, 0], [0.2, 0.1, 0.0, 0], [0.3, 0.25, 0.2, 0.01], [0.35, 0.3, 0.3, 0.01])]
    tool = kin.site("tool")
    return [Target(kin.position(q, tool), kin.rotation(q, tool), gripper=q[3]) for q in qs]


def test_ik_reaches_position_and_orientation(arm):
    kin = Kinematics(arm)
    tool = kin.site("tool")
    target = waypoints(kin)[2]
    q = solve_ik(kin, tool, target, Q_SEED, tol=1e-7)
    assert np.linalg.norm(kin.position(q, tool) - target.position) < IK_TOL
    assert np.linalg.norm(rotation_angle(kin.rotation(q, tool), target.rotation)) < IK_TOL / 0.3
    assert q[3] == target.gripper
    assert np.all(q[:3] >= arm.lower[:3]) and np.all(q[:3] <= arm.upper[:3])


def rotation_angle(a, b):
    from corl.mujoco import rotation_error

    return rotation_error(a, b)


def test_ik_refuses_unreachable_target(arm):
    kin = Kinematics(arm)
    with pytest.raises(NumericalError, match="out of reach"):
        solve_ik(kin, kin.site("tool"), Target([2.0, 0.0, 0.3]), Q_SEED)


def test_waypoints_walk_from_the_start_index(arm):
    kin = Kinematics(arm)
    tool = kin.site("tool")
    targets = waypoints(kin)
    knots = solve_waypoints(kin, tool, targets, Q_SEED, start=2, tol=1e-7)
    assert knots.shape == (4, 4)
    for q, t in zip(knots, targets):
        assert np.linalg.norm(kin.position(q, tool) - t.position) < IK_TOL


def test_projected_demonstration_satisfies_h(arm):
    """The fitted spline misses its waypoints; the projection puts it on h = 0 and says how far it was."""
    kin = Kinematics(arm)
    tool = kin.site("tool")
    targets = waypoints(kin)
    knots = solve_waypoints(kin, tool, targets, Q_SEED, tol=1e-7)
    times = np.array([0.0, 0.6, 1.2, 2.0])
    spline = BSpline(20, 4, duration=2.0)
    w0 = fit_demonstration(spline, times, knots, dt=0.01)
    fk = stack(position_feature(kin, tool), orientation_feature(kin, tool, targets[2].rotation, weight=0.3))
    problem = TrajectoryProblem(spline.n, costs=[acceleration_feature(spline, 4)], equalities=[
        configuration_feature(spline, 0.0, knots[0]),
        TaskSpaceFeature(spline, fk, [times[2]], np.concatenate([targets[2].position, np.zeros(3)])),
    ])
    h0, _ = problem.equalities(w0)
    assert np.max(np.abs(h0)) > 1e-4  # the least-squares fit cuts the corner at the waypoint
    w, report = project_demonstration(problem.equalities, w0, tolerance=1e-8)
    h, _ = problem.equalities(w)
    assert np.max(np.abs(h)) <= 1e-8
    assert report.error_before == pytest.approx(np.max(np.abs(h0)))
    assert report.error_after <= 1e-8 and report.converged
    assert report.distance == pytest.approx(np.linalg.norm(w - w0))
    assert "before projection" in str(report)
    # the closest point: much closer than the size of the correction needed at one waypoint x 100
    assert report.max_joint_change < 100 * report.error_before
    with pytest.raises(InputError, match="above max_error"):
        project_demonstration(problem.equalities, w0, max_error=1e-6)


def test_fit_checks_shapes():
    with pytest.raises(InputError, match=r"expected \(K, 4\)"):
        fit_demonstration(BSpline(10, 4, duration=1.0), [0.0, 1.0], np.zeros((2, 3)), 0.01)
    with pytest.raises(InputError, match="must increase"):
        fit_demonstration(BSpline(10, 4, duration=1.0), [0.0, 0.0], np.zeros((2, 4)), 0.01)
