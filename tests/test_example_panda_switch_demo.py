"""The switch task derived from a recording (issue 35): its contacts match the hand-written task's, its
h's Jacobian matches finite differences, and it learns as well as the hand-written task."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from panda import ROOT, needs_panda

pytestmark = needs_panda


@pytest.fixture(scope="module")
def task():
    from examples.panda_switch_demo import make_task

    return make_task()


def test_the_recording_touches_the_paddle_where_the_hand_written_demonstration_presses(task):
    from examples.panda_switch import LENGTH, R_DEMO, T_TOUCH, THICK, TIP_HALF

    (iv,) = task.contacts.intervals
    assert iv.start == pytest.approx(T_TOUCH, abs=0.05) and iv.end == pytest.approx(2.5)
    assert set(iv.geoms) == {"panda_leftfinger_tip", "panda_rightfinger_tip"}
    # the hand-written task's contact point: R_DEMO from the hinge on the paddle's top, within a pad's half-length
    np.testing.assert_allclose(iv.point, [-R_DEMO, 0.0, THICK / 2], atol=TIP_HALF / 3)
    assert iv.slide < TIP_HALF / 3
    assert task.theta0 == pytest.approx([R_DEMO], abs=TIP_HALF / 3)
    np.testing.assert_allclose([task.theta_bounds.lower[0], task.theta_bounds.upper[0]], [0.0, LENGTH], atol=1e-9)


def test_the_demonstration_is_on_h_and_succeeds(task):
    demo = task.demonstration()
    assert np.max(np.abs(task.constraint(demo.w, demo.theta)[0])) < 1e-6
    np.testing.assert_allclose(demo.theta, task.theta0, atol=1e-6)
    assert task.rollout(demo.w).success


def test_h_jacobian_matches_finite_differences(task):
    rng = np.random.default_rng(0)
    w = task.demonstration().w + 0.01 * rng.standard_normal(task.spline.n)
    theta = task.theta0 + 0.03
    h, jac = task.constraint(w, theta)
    jac = jac.toarray() if hasattr(jac, "toarray") else np.asarray(jac)
    step = 1e-6
    for j in rng.choice(task.spline.n, 24, replace=False):
        e = np.zeros_like(w)
        e[j] = step
        fd = (task.constraint(w + e, theta)[0] - task.constraint(w - e, theta)[0]) / (2 * step)
        np.testing.assert_allclose(jac[:, j], fd, atol=1e-6 * (1 + np.abs(fd).max()))


def _run(task_path, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT)]), "OPENBLAS_NUM_THREADS": "1"}
    out = subprocess.run([sys.executable, "-m", "corl.cli", "run", task_path, "--seed", "0", "--out",
                          str(tmp_path / task_path.split(":")[0]), "--quiet", "--json"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


@pytest.mark.slow
def test_learns_as_well_as_the_hand_written_task(tmp_path):
    derived = _run("examples.panda_switch_demo:make_task", tmp_path)
    hand = _run("examples.panda_switch:make_task", tmp_path)
    assert derived["failures"] <= hand["failures"] + 2
    assert derived["best_return"] >= 0.95 * hand["best_return"]
