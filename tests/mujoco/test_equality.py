"""add_joint_equality: the same joint equality under every MuJoCo in range (its data array changed length)."""

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from corl.errors import InputError  # noqa: E402
from corl.mujoco import add_joint_equality  # noqa: E402

XML = """<mujoco><option gravity="0 0 0"/><worldbody>
  <body name="a"><joint name="ja" type="hinge" axis="0 0 1"/><geom size=".1" mass="1"/></body>
  <body name="b" pos="1 0 0"><joint name="jb" type="hinge" axis="0 0 1"/><geom size=".1" mass="1"/></body>
</worldbody></mujoco>"""


def test_a_coupling_holds_q1_as_the_polynomial_of_q2():
    spec = mujoco.MjSpec.from_string(XML)
    add_joint_equality(spec, "jb", "ja", polycoef=(0.1, 2.0), name="couple")
    model = spec.compile()
    k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, "couple")
    np.testing.assert_allclose(model.eq_data[k][:5], [0.1, 2.0, 0.0, 0.0, 0.0])
    data = mujoco.MjData(model)
    data.qpos[0] = 0.3
    for _ in range(2000):  # the constraint pulls jb to 0.1 + 2 * ja (a soft constraint: a few steps)
        data.qfrc_applied[0] = 0.0
        mujoco.mj_step(model, data)
    assert data.qpos[1] == pytest.approx(0.1 + 2.0 * data.qpos[0], abs=1e-2)


def test_without_a_second_joint_the_joint_is_pinned_and_unknown_joints_are_refused():
    spec = mujoco.MjSpec.from_string(XML)
    add_joint_equality(spec, "ja", polycoef=(0.0, 0.0), name="latch")
    model = spec.compile()
    assert model.neq == 1 and np.all(model.eq_data[0][:5] == 0.0)
    with pytest.raises(InputError, match="no joint 'nope'"):
        add_joint_equality(spec, "nope", "ja")
    with pytest.raises(InputError, match="1 to 5 coefficients"):
        add_joint_equality(spec, "ja", "jb", polycoef=(0, 1, 0, 0, 0, 0))
