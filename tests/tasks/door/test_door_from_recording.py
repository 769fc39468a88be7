"""The door built from a recording of its demonstration (issue 35, benchmarks/door_from_recording.py):
the grasp is found where the door's demonstration grasps, and the derived demonstration opens the door."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")
ROOT = Path(__file__).resolve().parents[3]
if str(ROOT) not in sys.path:  # benchmarks/ is imported from the repository root
    sys.path.insert(0, str(ROOT))

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def task():
    from benchmarks.door_from_recording import make_task

    return make_task()


def test_the_grasp_is_found_on_the_bar_where_the_demonstration_grasps(task):
    from corl.tasks.door.demo import DEMO_GRASP_R, DEMO_WIDTH
    from corl.tasks.door.scene import DoorGeometry

    g = DoorGeometry()
    (iv,) = task.contacts.intervals
    assert iv.end == pytest.approx(5.0) and 1.3 < iv.start < 1.7                 # closing on the bar to the end
    np.testing.assert_allclose(iv.point, [-g.standoff, -DEMO_GRASP_R, 0.0], atol=g.lever_radius / 5)
    assert iv.slide < g.lever_radius / 5
    np.testing.assert_allclose(task.theta0, [DEMO_GRASP_R, DEMO_WIDTH], atol=g.lever_radius / 5)
    handle = task.contacts.qpos[:, task.robot.model.jnt_qposadr[task.robot.id("joint", "handle_hinge")]]
    assert handle.max() > g.latch_angle  # the replay pressed the held handle past the latch


def test_the_derived_demonstration_is_on_h_and_opens_the_door(task):
    demo = task.demonstration()
    assert np.max(np.abs(task.constraint(demo.w, demo.theta)[0])) < 1e-6
    outcome = task.rollout(demo.w)
    assert outcome.success and abs(outcome.return_) < 0.05  # R ~ 0 at the door's demonstration
