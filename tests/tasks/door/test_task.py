"""The door as a CORL task: Eq. 6 against the simulator, Eq. 18, and a short learning run."""

import numpy as np
import pytest

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def task():
    from corl.tasks.door.task import DoorTask

    return DoorTask()


def test_demonstration_succeeds_and_satisfies_h(task):
    demo = task.demonstration()
    assert demo.w.shape == (1200,)
    h, Jh = task.constraint(demo.w, demo.theta)
    assert np.abs(h).max() < 2e-3  # the B-spline fit of the jerky demonstration hits its waypoints
    out = task.rollout(demo.w)
    assert out.success and -0.5 < out.return_ < 0.5  # R = 1 - F / 15 N: the demonstration is near 0


def test_projection_jacobian_matches_finite_differences(task):
    demo = task.demonstration()
    theta = np.array([0.03, 0.014])
    h, Jh = task.constraint(demo.w, theta)
    rng = np.random.default_rng(0)
    d = rng.normal(size=demo.w.shape) * 1e-6
    h2, _ = task.constraint(demo.w + d, theta)
    np.testing.assert_allclose(h2 - h, Jh @ d, rtol=1e-3, atol=1e-9)


def test_h_matches_where_the_fingers_touch_the_handle(task):
    import mujoco

    demo = task.demonstration()
    contacts = []

    def at_grasp(t, data):
        if abs(t - 2.0) < 1e-9:
            scene = task.scene
            for c in data.contact[: data.ncon]:
                pair = {int(c.geom1), int(c.geom2)}
                if pair & set(scene.tip_geoms) and pair & set(scene.handle_geoms):
                    contacts.append(np.array(c.pos))

    task.simulate(demo.w, on_frame=at_grasp, frame_every=1)
    assert contacts, "no finger touches the handle at t = 2 s"
    touch = np.mean(contacts, axis=0)
    q = task.spline.positions(demo.w, [2.0])[0]
    predicted = task.kin.contact_point(q)
    assert np.linalg.norm(touch - predicted) < 0.02  # the pads' midpoint is where the bar is held
    theta = task.theta_of(demo.w)
    np.testing.assert_allclose(theta, demo.theta)


def test_eq18_realises_a_new_theta_and_keeps_the_grasp(task):
    from corl.realise import realise

    demo = task.demonstration()
    theta = np.array([0.05, 0.016])
    result = realise(task, demo.w, demo.theta, theta)
    assert result.constraint_error < 1e-5
    np.testing.assert_allclose(task.theta_of(result.w), theta, atol=1e-3)
    out = task.rollout(result.w)
    assert out.success


def test_short_learning_run_improves_J_and_keeps_success(task):
    from corl.methods import make_method
    from corl.learner import cost_of

    learner = make_method("CORL+PIBU", task, seed=0)
    learner.run(max_trials=6)  # demonstration + motion-optimization steps
    steps = [(p, o) for p, o in learner.history if p.step == "optimization"]
    assert steps and all(o.success for _, o in steps)
    J0 = cost_of(task, learner.history[0][0].w)
    assert learner.best.J < 0.5 * J0
    assert all(np.linalg.norm(b.w - a.w) <= 0.1 + 1e-9 for (a, _), (b, _) in zip(learner.history, learner.history[1:]))


def test_trajectory_problem_is_the_tasks_J_and_h_and_step_one_runs_on_sqp(task):
    from corl.realise import motion_problem
    from corl.tasks.door.task import EPS_MAX
    from corl.trajectory.solver import solve

    demo = task.demonstration()
    theta = np.array([0.03, 0.014])
    problem = motion_problem(task, theta)
    assert problem is task.trajectory_problem(theta)  # cached per theta
    w = demo.w + 1e-3 * np.random.default_rng(1).standard_normal(demo.w.shape)
    r, _ = problem.residuals(w)
    h, Jh = problem.equalities(w)
    h_task, Jh_task = task.constraint(w, theta)
    np.testing.assert_array_equal(r, task.cost_residuals(w)[0])
    np.testing.assert_array_equal(h, h_task)
    assert abs(Jh - Jh_task).max() == 0.0
    result = solve(motion_problem(task, demo.theta), demo.w, radius=EPS_MAX)  # Alg. 1, step 1 (Eq. 8)
    assert result.converged and result.status.startswith("converged (SQP)"), result.status
    assert result.constraint_error < 1e-10 and result.cost < 0.9 * problem.cost(demo.w)
    assert np.linalg.norm(result.w - demo.w) <= EPS_MAX * (1 + 1e-12)


def test_force_noise_is_seeded_and_repeatable(task):
    from corl.errors import InputError
    from corl.tasks.door.task import FORCE_REFERENCE, DoorTask

    w = task.demonstration().w
    exact = task.rollout(w)
    a, b = DoorTask(force_noise=0.5, seed=1), DoorTask(force_noise=0.5, seed=2)
    ra, rb = a.rollout(w), b.rollout(w)
    assert ra.success and rb.success  # S stays exact
    assert ra.return_ != exact.return_ and ra.return_ != rb.return_
    assert a.rollout(w).return_ == ra.return_  # the same trial reads the same (replay from a store)
    assert abs(ra.return_ - exact.return_) < 5 * 0.5 / FORCE_REFERENCE
    with pytest.raises(InputError, match="force_noise"):
        DoorTask(force_noise=-1.0)


def test_retimed_moves_the_contact_instants_only(task):
    from corl.errors import InputError

    moved = task.retimed(lambda t: np.where(t < 4.5, t + 0.05, t))  # the end stays at T
    assert np.allclose(moved.contact_times[:-1], task.contact_times[:-1] + 0.05)
    assert moved.t_contact == pytest.approx(task.t_contact + 0.05)
    assert task.contact_times[0] == task.contacts[0].time  # the original is untouched
    demo = task.demonstration()
    h, _ = moved.constraint(demo.w, demo.theta)
    h0, _ = task.constraint(demo.w, demo.theta)
    assert np.abs(h).max() > 10 * np.abs(h0).max()  # the constraints now hold at other instants
    with pytest.raises(InputError, match="increasing"):
        task.retimed(lambda t: t[::-1])
