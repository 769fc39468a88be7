"""The learning problem over theta is real: a bounded success region and a force trade-off."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from corl.errors import InputError  # noqa: E402
from corl.tasks.door.demo import scripted_demonstration, shifted_reference  # noqa: E402
from corl.tasks.door.kinematics import Kinematics  # noqa: E402
from corl.tasks.door.scene import load_scene  # noqa: E402
from corl.tasks.door.sim import rollout  # noqa: E402


@pytest.fixture(scope="module")
def demo():
    return scripted_demonstration(load_scene())


def _run(demo, theta):
    ref = shifted_reference(demo, theta)
    return rollout(ref.reference(), t_contact=ref.t_contact)


def test_shifted_reference_moves_the_contact_point_along_the_lever(demo):
    scene = load_scene()
    kin = Kinematics(scene)
    k = int(np.searchsorted(demo.times, demo.t_contact))
    moved = shifted_reference(demo, [0.05, 0.012])
    delta = kin.contact_point(moved.knots[k]) - kin.contact_point(demo.knots[k])
    np.testing.assert_allclose(delta, [0.0, -0.05, 0.0], atol=1e-3)  # the lever points to -y
    assert moved.knots[k, 7] == pytest.approx(0.012)
    with pytest.raises(InputError):
        shifted_reference(demo, [0.01])


@pytest.mark.slow
def test_force_falls_towards_the_tip_and_loose_or_pivot_grasps_fail(demo):
    near, far = _run(demo, [0.0, 0.012]), _run(demo, [0.06, 0.012])
    assert near.success and far.success
    assert far.force_mean < 0.8 * near.force_mean
    assert not _run(demo, [0.03, 0.026]).success      # too wide: nothing presses the handle
    assert not _run(demo, [-0.02, 0.012]).success     # at the pivot: the pad hits the neck
