"""Tracking a joint reference with PD servos and gravity compensation (the policy of Sec. V-A).

Glossary
--------
q_ref, dq_ref  (8,) reference configuration and its velocity (7 arm angles, gripper width)
u              (8,) servo set-points written to ``data.ctrl``
tau            joint torque of a servo: kp (u - q) - kv dq, clipped to the PR2 effort limit

The PD law (:mod:`corl.mujoco.control`) is realised by MuJoCo position servos (``scene.ARM_KP`` / ``ARM_KV``), whose damping the
implicit integrator treats implicitly, so stiff gains stay stable at 500 Hz. The reference velocity
enters as a set-point lead ``u = q_ref + (kv / kp) dq_ref``, which makes the servo torque exactly
``kp (q_ref - q) + kv (dq_ref - dq)``. Gravity and Coriolis forces of the arm and gripper are
cancelled by ``qfrc_applied = qfrc_bias`` (as a PR2's controllers do), so the servos only see the
tracking error and the contact forces.
"""

from __future__ import annotations

import numpy as np

from corl.mujoco import PDController as _PDController
from corl.mujoco import dense_reference as _dense_reference
from corl.tasks.door.scene import ARM_KP, ARM_KV, DoorScene

__all__ = ["PDController", "dense_reference"]


def dense_reference(reference, duration: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`corl.mujoco.dense_reference` of an (N, 8) reference (7 arm joints + gripper width)."""
    return _dense_reference(reference, duration, dt, 8)


class PDController(_PDController):
    """:class:`corl.mujoco.PDController` with the PR2's arm gains, for the door scene's servos."""

    def __init__(self, scene: DoorScene):
        super().__init__(scene.robot, ARM_KP, ARM_KV)
        self.scene = scene
