"""The door's context family (corl.problem.HasContexts): c = (dz, dx, dy, yaw) moves the door; c = 0
is the paper's scene, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("mujoco")

from corl.errors import DemonstrationFailedError, InputError  # noqa: E402
from corl.problem import Demonstration, check_task, context_of  # noqa: E402
from corl.realise import check_demonstration, constraint_violation  # noqa: E402

YAW = math.radians(10.0)
CORNERS = (np.array([0.05, 0.05, 0.05, YAW]), np.array([-0.05, -0.05, -0.05, -YAW]))


@pytest.fixture(scope="module")
def base():
    from corl.tasks.door.task import DoorTask

    return DoorTask()


def test_context_zero_is_the_papers_task(base):
    from corl.tasks.door.demo import CONTROL_DT, scripted_demonstration
    from corl.tasks.door.scene import DoorGeometry, load_scene
    from corl.tasks.door.task import DoorTask

    scene = load_scene()
    assert base.scene is scene and scene.geometry == DoorGeometry() and scene.geometry.yaw == 0.0
    np.testing.assert_array_equal(base.context, np.zeros(4))
    check_task(base)
    np.testing.assert_array_equal(context_of(base), np.zeros(4))
    assert len(base.context_labels) == 4
    # w0 is the fit of the scripted demonstration in the unmoved scene, as it always was
    t = np.arange(int(round(base.duration / CONTROL_DT)) + 1) * CONTROL_DT
    w_today = base.spline.fit(t, scripted_demonstration(scene).reference(CONTROL_DT))
    demo = base.demonstration()
    np.testing.assert_array_equal(demo.w, w_today)
    assert demo.theta[0] == pytest.approx(0.0, abs=1e-4) and demo.theta[1] == pytest.approx(0.016, abs=5e-4)
    h, _ = base.constraint(demo.w, demo.theta)
    assert np.abs(h).max() < 1e-3
    for other in (DoorTask(context=np.zeros(4)), base.with_context([0.0, 0.0, 0.0, 0.0])):
        assert other.scene is scene
        d = other.demonstration()
        np.testing.assert_array_equal(d.w, demo.w)
        np.testing.assert_array_equal(d.theta, demo.theta)
        np.testing.assert_array_equal(other.constraint(demo.w, demo.theta)[0], h)
        np.testing.assert_array_equal(other.cost_residuals(demo.w)[0], base.cost_residuals(demo.w)[0])


def test_with_context_moves_the_door_and_keeps_the_layout(base):
    import mujoco

    c = np.array([0.03, -0.02, 0.04, -0.12])
    task = base.with_context(c)
    np.testing.assert_array_equal(task.context, c)
    assert task.context_bounds is base.context_bounds and task.theta_bounds is base.theta_bounds
    assert task.spline.n == base.spline.n and task.num_steps == base.num_steps
    assert (task.force_noise, task.seed) == (base.force_noise, base.seed)
    np.testing.assert_array_equal(task.contact_times, base.contact_times)
    scene = task.scene
    np.testing.assert_allclose(scene.pivot_world, base.scene.pivot_world + [c[1], c[2], c[0]], atol=1e-9)  # m: far below anything a robot resolves
    # the analytic geometry (handle_point, door_point, along_lever) is the compiled model's
    data = mujoco.MjData(scene.model)
    for phi, alpha in ((0.0, 0.0), (0.3, 0.5)):
        data.qpos[:] = 0.0
        data.qpos[scene.hinge_qpos], data.qpos[scene.handle_qpos] = phi, alpha
        mujoco.mj_kinematics(scene.model, data)
        frame = data.xmat[scene.handle_body].reshape(3, 3)
        for r in (0.0, 0.05, 0.1):
            bar = data.xpos[scene.handle_body] + frame @ [-scene.geometry.standoff, -r, 0.0]
            np.testing.assert_allclose(scene.handle_point(r, phi, alpha), bar, atol=1e-9)
    assert scene.along_lever(scene.handle_point(0.07)) == pytest.approx(0.07, abs=1e-9)
    demo = base.demonstration()
    h_base, h_moved = base.constraint(demo.w, demo.theta)[0], task.constraint(demo.w, demo.theta)[0]
    assert h_moved.shape == h_base.shape and np.abs(h_moved).max() > 0.01  # the door moved away from w0


@pytest.mark.parametrize("bad, name", [([0.0, 0.0, 0.0, 0.2], "yaw"), ([0.06, 0.0, 0.0, 0.0], "dz"),
                                       ([0.0, -0.051, 0.07, 0.0], "dx")])
def test_with_context_refuses_a_context_outside_the_box(base, bad, name):
    from corl.tasks.door.task import DoorTask

    for make in (base.with_context, lambda c: DoorTask(context=c)):
        with pytest.raises(InputError) as error:
            make(bad)
        message = str(error.value)
        assert "\n" not in message and f"{name} = " in message and "outside" in message
        assert "0.1745" in message  # the box
    for bad_shape in ([0.0, 0.0, 0.0], [0.0, 0.0, float("nan"), 0.0]):
        with pytest.raises(InputError, match="context"):
            base.with_context(bad_shape)


def test_a_retimed_task_keeps_its_contact_instants_in_another_context(base):
    moved = base.retimed(lambda t: 0.99 * t).with_context(CORNERS[0])
    np.testing.assert_allclose(moved.contact_times, 0.99 * base.contact_times)
    assert moved.t_contact == pytest.approx(0.99 * base.t_contact)
    np.testing.assert_array_equal(moved.context, CORNERS[0])


@pytest.mark.parametrize("c", CORNERS, ids=["upper corner", "lower corner"])
def test_scripted_demonstration_at_a_corner_satisfies_h(base, c):
    from corl.tasks.door.contexts import context_demonstration, rest_posture

    task = base.with_context(c)
    demo = context_demonstration(task.scene, c)  # the first grasp shift the arm reaches (no rollout)
    np.testing.assert_array_equal(demo.knots[0], rest_posture())
    w0 = task.fit_demonstration(demo)
    theta0 = task.theta_of(w0)
    assert theta0[0] == pytest.approx(demo.theta[0], abs=1e-3)  # theta_of reads the grasp along the turned lever
    check_demonstration(task, Demonstration(w0, theta0))  # max|h(w0, theta0)| <= 1e-3
    np.testing.assert_array_equal(w0[:8], base.demonstration().w[:8])  # the same rest posture


@pytest.mark.slow
@pytest.mark.parametrize("c", CORNERS, ids=["upper corner", "lower corner"])
def test_demonstration_at_a_corner_succeeds(base, c):
    task = base.with_context(c)
    demo = check_demonstration(task)
    assert constraint_violation(task, demo.w, demo.theta) <= 1e-3
    outcome = task.rollout(demo.w)
    assert outcome.success, outcome.info


@pytest.mark.slow
def test_base_demonstration_transfers_by_eq18_and_step_one():
    from corl.learner import cost_of
    from corl.realise import motion_problem, realise
    from corl.tasks.door.task import EPS_MAX, DoorTask
    from corl.trajectory.solver import solve

    base = DoorTask()
    demo = base.demonstration()
    task = base.with_context([-0.0144, -0.0199, -0.0038, -0.1571])
    result = realise(task, demo.w, demo.theta, demo.theta)
    assert result.feasible and result.constraint_error < 1e-6
    assert task.rollout(result.w).success
    step = solve(motion_problem(task, demo.theta), result.w, center=result.w, radius=EPS_MAX)
    assert step.constraint_error < 1e-8 and cost_of(task, step.w) < cost_of(task, result.w)


@pytest.mark.slow
def test_a_context_out_of_the_arms_reach_says_so_in_one_line(base):
    task = base.with_context([-0.05, -0.05, 0.05, -YAW])  # low, close, yawed towards the shoulder
    with pytest.raises(DemonstrationFailedError) as error:
        task.demonstration()
    assert "\n" not in str(error.value) and "context" in str(error.value)
