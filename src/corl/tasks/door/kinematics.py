"""Forward kinematics of the contact point and inverse kinematics of the PR2 right arm.

Glossary
--------
q          (8,) the 7 arm joint angles (rad), then the gripper opening width (m)
phi_CP(q)  (3,) world position of the contact point: the midpoint of the two fingertip pads
           (the contact point of Eq. 6)
J_CP(q)    (3, 8) its Jacobian d phi_CP / d q; the width column is analytic (finger angle
           chain rule through the joint equalities)
R_hand(q)  (3, 3) orientation of the palm frame (x: approach, y: finger opening direction)

Everything runs on a private ``MjData`` and calls ``mj_kinematics`` / ``mj_comPos`` only, so it is
cheap (about 10 us per evaluation) and never touches a simulation in progress.
"""

from __future__ import annotations

import numpy as np

from corl.errors import InputError, NumericalError
from corl.tasks.door.scene import DoorScene, angle_of_width, dwidth_dangle, load_scene

__all__ = ["Kinematics", "rotation_error"]


def rotation_error(r_target: np.ndarray, r_current: np.ndarray) -> np.ndarray:
    """Axis-angle vector (3,) that rotates ``r_current`` onto ``r_target`` (world frame)."""
    r_err = r_target @ r_current.T
    cos = np.clip((np.trace(r_err) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(cos)
    axis = np.array([r_err[2, 1] - r_err[1, 2], r_err[0, 2] - r_err[2, 0], r_err[1, 0] - r_err[0, 1]])
    sin = np.sin(angle)
    if sin < 1e-6:
        if angle < 1e-6:
            return 0.5 * axis
        # near pi: axis from the diagonal
        diag = np.sqrt(np.maximum((np.diag(r_err) + 1.0) / 2.0, 0.0))
        return angle * diag / max(np.linalg.norm(diag), 1e-12)
    return angle * axis / (2.0 * sin)


class Kinematics:
    """Contact-point forward kinematics, its Jacobian, and damped-least-squares IK.

    Parameters
    ----------
    scene : DoorScene, optional
        Defaults to the cached :func:`load_scene`.
    """

    def __init__(self, scene: DoorScene | None = None):
        import mujoco

        self._mj = mujoco
        self.scene = scene or load_scene()
        self.data = mujoco.MjData(self.scene.model)
        self._jac_l = np.zeros((3, self.scene.model.nv))
        self._jac_r = np.zeros((3, self.scene.model.nv))
        self._jac_rot = np.zeros((3, self.scene.model.nv))

    # ---------------------------------------------------------------- forward kinematics
    def set_q(self, q: np.ndarray) -> None:
        """Pose the private model at ``q`` (8,) and update kinematics."""
        q = np.asarray(q, dtype=float)
        if q.shape != (8,):
            raise InputError(f"q has shape {q.shape}, expected (8,) = 7 arm joints + gripper width")
        s, d = self.scene, self.data
        d.qpos[s.arm_qpos] = q[:7]
        angle = angle_of_width(q[7])
        d.qpos[s.finger_qpos] = angle
        d.qpos[s.follower_qpos] = angle
        self._mj.mj_kinematics(s.model, d)
        self._mj.mj_comPos(s.model, d)

    def contact_point(self, q: np.ndarray) -> np.ndarray:
        """phi_CP(q): world position (3,) of the midpoint between the fingertip pads."""
        self.set_q(q)
        return self.data.site_xpos[self.scene.pad_sites].mean(axis=0)

    def hand_rotation(self, q: np.ndarray) -> np.ndarray:
        """R_hand(q): (3, 3) palm orientation (columns: approach, opening, normal)."""
        self.set_q(q)
        return self.data.xmat[self.scene.wrist_body].reshape(3, 3).copy()

    def contact_point_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """phi_CP(q) (3,) and J_CP(q) (3, 8).

        The arm columns come from ``mj_jacSite``; the width column adds the columns of the four
        coupled finger joints (all equal to the driven angle) times d angle / d width.
        """
        self.set_q(q)
        s, d, mj = self.scene, self.data, self._mj
        mj.mj_jacSite(s.model, d, self._jac_l, None, int(s.pad_sites[0]))
        mj.mj_jacSite(s.model, d, self._jac_r, None, int(s.pad_sites[1]))
        jac_full = 0.5 * (self._jac_l + self._jac_r)
        jac = np.empty((3, 8))
        jac[:, :7] = jac_full[:, s.arm_dof]
        angle = d.qpos[s.finger_qpos]
        jac[:, 7] = jac_full[:, s.gripper_dofs].sum(axis=1) / dwidth_dangle(angle)
        return d.site_xpos[s.pad_sites].mean(axis=0), jac

    # ---------------------------------------------------------------- inverse kinematics
    def ik(self, target_pos: np.ndarray, target_rot: np.ndarray | None, q_init: np.ndarray, *,
           rot_weight: float = 0.3, damping: float = 1e-3, iterations: int = 200,
           tol: float = 1e-5) -> np.ndarray:
        """Damped-least-squares IK of the arm: put the contact point at ``target_pos``.

        Parameters
        ----------
        target_pos : (3,) world position of the contact point
        target_rot : (3, 3) palm orientation, or None to ignore orientation
        q_init : (8,) start; its gripper width is kept
        rot_weight : metres per radian of orientation error in the stacked residual

        Returns
        -------
        q : (8,) with joint limits respected. Raises NumericalError when the residual stays
        above 1 mm (unreachable target).
        """
        s = self.scene
        q = np.array(q_init, dtype=float)
        lo, hi = s.joint_lower + 1e-4, s.joint_upper - 1e-4
        q[:7] = np.clip(q[:7], lo, hi)
        for _ in range(iterations):
            pos, jac = self.contact_point_jacobian(q)
            err = [np.asarray(target_pos) - pos]
            rows = [jac[:, :7]]
            if target_rot is not None:
                self._mj.mj_jacBody(s.model, self.data, None, self._jac_rot, s.wrist_body)
                rot = self.data.xmat[s.wrist_body].reshape(3, 3)
                err.append(rot_weight * rotation_error(np.asarray(target_rot), rot))
                rows.append(rot_weight * self._jac_rot[:, s.arm_dof])
            e, a = np.concatenate(err), np.vstack(rows)
            if np.linalg.norm(e) < tol:
                break
            step = a.T @ np.linalg.solve(a @ a.T + damping * np.eye(a.shape[0]), e)
            step *= min(1.0, 0.3 / max(np.abs(step).max(), 1e-12))  # at most 0.3 rad per joint
            q[:7] = np.clip(q[:7] + step, lo, hi)
        if np.linalg.norm(e) > 1e-3:
            raise NumericalError(f"IK did not reach the target (residual {np.linalg.norm(e):.4f}); "
                                 "it may be out of the arm's reach or against a joint limit")
        return q
