"""track's bound-view loop writes what PDController.apply and compensate write, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from corl.mujoco import PDController, track
from corl.mujoco.control import _as_slice

mujoco = pytest.importorskip("mujoco")


class Written(PDController):
    """A controller that overrides apply and compensate (the same writes), so track calls them."""

    def apply(self, data, u):
        super().apply(data, u)

    def compensate(self, data):
        super().compensate(data)


def _reference(arm, seconds: float = 0.6) -> np.ndarray:
    dt = arm.model.opt.timestep
    t = np.arange(0, seconds + dt / 2, dt)
    q0 = np.array([0.2, -0.6, 0.4, 0.03])
    return q0 + np.outer(np.sin(3 * t), [0.3, 0.4, -0.2, 0.01])


def _run(arm, tiny, controller_type):
    log = []
    data, q_ref = track(arm, controller_type(arm, tiny.kp, tiny.kv), _reference(arm), 0.6,
                        on_step=lambda k, d: log.append((k, d.qpos.copy(), d.qvel.copy(), d.ctrl.copy(),
                                                         d.qfrc_applied.copy(), d.sensordata.copy())))
    return data, q_ref, log


def test_the_fast_loop_equals_the_method_calls(arm, tiny):
    fast = PDController(arm, tiny.kp, tiny.kv)
    assert fast._views(mujoco.MjData(arm.model)) is not None  # the tiny arm takes the fast loop
    assert Written(arm, tiny.kp, tiny.kv)._views(mujoco.MjData(arm.model)) is None
    data_f, q_f, log_f = _run(arm, tiny, PDController)
    data_s, q_s, log_s = _run(arm, tiny, Written)
    assert np.array_equal(q_f, q_s) and len(log_f) == len(log_s) == len(q_f)
    for (k_f, *arrays_f), (k_s, *arrays_s) in zip(log_f, log_s):
        assert k_f == k_s
        assert all(np.array_equal(a, b) for a, b in zip(arrays_f, arrays_s))
    assert np.array_equal(data_f.qpos, data_s.qpos) and data_f.time == data_s.time


def test_an_instance_attribute_also_takes_the_method_path(arm, tiny):
    ctrl = PDController(arm, tiny.kp, tiny.kv)
    calls = []
    ctrl.compensate = lambda data: calls.append(PDController.compensate(ctrl, data))
    track(arm, ctrl, _reference(arm, 0.01), 0.01)
    assert len(calls) == 1 + 5  # once before the first mj_forward, then each of the 5 steps


@pytest.mark.parametrize("ids, ordered, expected", [
    ([0, 1, 2], True, slice(0, 3)),
    ([3, 4], True, slice(3, 5)),
    ([1, 0, 2], True, None),  # values pair with entries in order
    ([1, 0, 2], False, slice(0, 3)),  # a copy onto the same entries does not care
    ([0, 2], False, None),
    ([], False, None),
])
def test_as_slice(ids, ordered, expected):
    assert _as_slice(np.array(ids, dtype=int), ordered) == expected
