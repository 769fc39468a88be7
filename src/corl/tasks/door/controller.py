"""Tracking a joint reference with PD servos and gravity compensation (the policy of Sec. V-A).

Glossary
--------
q_ref, dq_ref  (8,) reference configuration and its velocity (7 arm angles, gripper width)
u              (8,) servo set-points written to ``data.ctrl``
tau            joint torque of a servo: kp (u - q) - kv dq, clipped to the PR2 effort limit

The PD law is realised by MuJoCo position servos (``scene.ARM_KP`` / ``ARM_KV``), whose damping the
implicit integrator treats implicitly, so stiff gains stay stable at 500 Hz. The reference velocity
enters as a set-point lead ``u = q_ref + (kv / kp) dq_ref``, which makes the servo torque exactly
``kp (q_ref - q) + kv (dq_ref - dq)``. Gravity and Coriolis forces of the arm and gripper are
cancelled by ``qfrc_applied = qfrc_bias`` (as a PR2's controllers do), so the servos only see the
tracking error and the contact forces.
"""

from __future__ import annotations

import numpy as np

from corl.errors import InputError
from corl.tasks.door.scene import ARM_KP, ARM_KV, DoorScene, angle_of_width

__all__ = ["PDController", "dense_reference"]


def dense_reference(reference, duration: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample a reference at the control rate.

    Parameters
    ----------
    reference : (N, 8) array at ``dt`` (shorter arrays hold their last row), or a callable
        ``t -> (8,)``
    duration, dt : s

    Returns
    -------
    q_ref : (K + 1, 8), dq_ref : (K + 1, 8) with K = round(duration / dt) (finite differences)
    """
    n = int(round(duration / dt)) + 1
    if callable(reference):
        q_ref = np.array([reference(k * dt) for k in range(n)], dtype=float)
    else:
        q_ref = np.asarray(reference, dtype=float)
        if q_ref.ndim != 2 or q_ref.shape[1] != 8:
            raise InputError(f"reference has shape {q_ref.shape}, expected (N, 8) = "
                             "7 arm joints + gripper width per control step")
        if len(q_ref) < n:
            q_ref = np.vstack([q_ref, np.repeat(q_ref[-1:], n - len(q_ref), axis=0)])
        q_ref = q_ref[:n]
    if not np.all(np.isfinite(q_ref)):
        raise InputError("reference contains NaN or inf")
    dq_ref = np.gradient(q_ref, dt, axis=0) if n > 1 else np.zeros_like(q_ref)
    return q_ref, dq_ref


class PDController:
    """Set-points and gravity compensation for the door scene's servos.

    Parameters
    ----------
    scene : DoorScene
    """

    def __init__(self, scene: DoorScene):
        self.scene = scene
        self._lead = np.asarray(ARM_KV) / np.asarray(ARM_KP)
        self._comp_dofs = np.concatenate([scene.arm_dof, scene.gripper_dofs])

    def setpoints(self, q_ref: np.ndarray, dq_ref: np.ndarray) -> np.ndarray:
        """Servo set-points u (K, 8) for a whole reference (K, 8): arm lead + finger angle."""
        u = np.empty_like(q_ref)
        u[:, :7] = q_ref[:, :7] + self._lead * dq_ref[:, :7]
        u[:, 7] = angle_of_width(q_ref[:, 7])
        return u

    def compensate(self, data) -> None:
        """Cancel gravity and Coriolis forces on the arm and fingers (``qfrc_applied = qfrc_bias``)."""
        data.qfrc_applied[self._comp_dofs] = data.qfrc_bias[self._comp_dofs]

    def initialise(self, data, q0: np.ndarray) -> None:
        """Put the robot at the reference's first configuration, at rest."""
        s = self.scene
        data.qpos[s.arm_qpos] = q0[:7]
        angle = angle_of_width(q0[7])
        data.qpos[s.finger_qpos] = angle
        data.qpos[s.follower_qpos] = angle
        data.qvel[:] = 0.0
