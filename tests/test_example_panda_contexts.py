"""The Panda switch's context family: the switch moved +-5 cm in x, y, z (corl.problem.HasContexts)."""

import numpy as np
import pytest

from corl.errors import InputError

from panda import needs_panda

pytestmark = needs_panda

CORNER = np.array([0.05, -0.05, -0.05])  # farther, to the right, lower


def _scene(task):
    """Where the paddle's hinge and the post sit in the compiled model."""
    model = task.robot.model
    return model.body_pos[task.robot.id("body", "paddle")].copy(), model.geom_pos[task.robot.id("geom", "post")].copy()


def test_zero_context_is_todays_task():
    from corl.problem import check_task, context_of
    from examples.panda_switch import HINGE, PandaSwitchTask, make_task

    today, zero = make_task(), make_task(np.zeros(3))
    assert isinstance(PandaSwitchTask().context, np.ndarray)
    assert np.array_equal(today.context, np.zeros(3)) and np.array_equal(today.hinge, HINGE)
    check_task(today)
    assert np.array_equal(context_of(today), np.zeros(3))
    hinge, post = _scene(today)
    assert np.array_equal(hinge, HINGE) and np.array_equal(post, [HINGE[0] + 0.03, 0.0, HINGE[2] / 2])
    # the same scene and the same demonstration, bit for bit
    for a, b in zip(_scene(today), _scene(zero)):
        assert a.tobytes() == b.tobytes()
    d, z = today.demonstration(), zero.demonstration()
    assert d.w.tobytes() == z.w.tobytes() and d.theta.tobytes() == z.theta.tobytes()
    h, _ = today.constraint(d.w, [0.1])
    h0, _ = zero.constraint(z.w, [0.1])
    assert h.tobytes() == h0.tobytes()


def test_with_context_moves_the_switch_and_keeps_theta():
    from corl.problem import check_task, context_of
    from examples.panda_switch import HINGE, make_task

    base = make_task()
    c = np.array([0.02, -0.03, 0.04])
    task = base.with_context(c)
    c[0] = 0.0  # the task keeps its own copy
    assert np.array_equal(task.context, [0.02, -0.03, 0.04])
    assert np.array_equal(context_of(check_task(task)), task.context)
    assert task.context_bounds is base.context_bounds and len(task.context_labels) == 3
    assert task.spline.n == base.spline.n and task.theta_bounds is base.theta_bounds
    hinge, post = _scene(task)
    assert np.allclose(hinge, HINGE + task.context, atol=1e-12)
    assert np.allclose(post, [HINGE[0] + 0.05, -0.03, (HINGE[2] + 0.04) / 2])
    assert task.robot.model is not base.robot.model
    # theta is still the distance from the (moved) hinge: h's targets moved with the switch
    d = base.demonstration()
    assert task.theta_of(d.w)[0] == pytest.approx(base.theta_of(d.w)[0] + 0.02, abs=1e-9)
    assert np.max(np.abs(task.constraint(d.w, d.theta)[0])) > 0.01  # today's motion misses the moved switch
    assert np.array_equal(task.with_context(np.zeros(3)).context, np.zeros(3))


@pytest.mark.parametrize("bad", [[0.06, 0.0, 0.0], [0.0, 0.0, -0.051], [0.0, 0.0], [np.nan, 0.0, 0.0], 0.01])
def test_context_outside_the_box_is_refused_in_one_line(bad):
    from examples.panda_switch import PandaSwitchTask, make_task

    for build in (make_task().with_context, make_task, PandaSwitchTask):
        with pytest.raises(InputError) as err:
            build(bad)
        message = str(err.value)
        assert "\n" not in message and message.startswith("context ")


@pytest.mark.slow
def test_corner_demonstration_succeeds_and_todays_demo_transfers():
    from corl.realise import check_demonstration, constraint_violation, realise
    from examples.panda_switch import make_task

    base = make_task()
    task = base.with_context(CORNER)
    demo = check_demonstration(task)  # max|h(w0, theta0)| <= 1e-3 in the moved scene
    assert constraint_violation(task, demo.w, demo.theta) < 1e-6
    assert demo.theta[0] == pytest.approx(0.05, abs=1e-6)
    outcome = task.rollout(demo.w)
    assert outcome.success, outcome.info
    # today's demonstration, realised in the corner's scene at its theta (Eq. 18)
    d0 = base.demonstration()
    moved = realise(task, d0.w, d0.theta, d0.theta)
    assert moved.feasible and moved.constraint_error < 1e-6
    assert task.rollout(moved.w).success
