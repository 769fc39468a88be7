"""Forward kinematics of sites and bodies in task coordinates, their Jacobians, rotation errors.

Glossary
--------
q          (Q,) task configuration (see :mod:`corl.mujoco.robot`)
frame      a site, the mean of several sites (e.g. two fingertip pads), or a body's origin
p(q)       (3,) world position of a frame; ``Jp`` (3, Q) its Jacobian dp/dq
R(q)       (3, 3) world orientation of a frame (columns: its axes); ``Jw`` (3, Q) the angular
           velocity Jacobian: ``omega = Jw dq/dt``, ``dR/dt = [omega]x R``
e          (3,) rotation error ``log(R_target R^T)`` as an axis-angle vector: the rotation (world
           frame) that takes R onto R_target

Jacobian columns come from ``mj_jacSite`` / ``mj_jacBody`` over all dofs; the arm's columns are
picked, and the gripper coordinate's column is ``sum_i ratios_i J[:, dof_i] / (dc/da)`` (the chain
rule through ``q_i = ratios_i a(c)``). All evaluations run on a private ``MjData`` with
``mj_kinematics`` and ``mj_comPos`` only (about 10 us), never touching a simulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl.errors import InputError
from corl.mujoco.robot import Robot

__all__ = ["Frame", "Kinematics", "rotation_error", "rotation_error_jacobian", "skew"]


def skew(v: np.ndarray) -> np.ndarray:
    """``[v]x`` (3, 3), the cross-product matrix of ``v`` (3,)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotation_error(r_target: np.ndarray, r_current: np.ndarray) -> np.ndarray:
    """Axis-angle vector ``e = log(R_target R_current^T)`` (3,) that rotates ``r_current`` (3, 3)
    onto ``r_target`` (3, 3) in the world frame; ``|e|`` is the angle (rad) between them."""
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


def rotation_error_jacobian(e: np.ndarray) -> np.ndarray:
    """``d(-e) / d omega`` (3, 3) for ``e = rotation_error(R_target, R)`` when R turns at ``omega``.

    ``R_target R^T`` then changes by a right factor ``exp(-[omega]x dt)``, so
    ``d(-e) = J_r^{-1}(e) omega`` with the inverse right Jacobian of SO(3),
    ``J_r^{-1}(e) = I + [e]x / 2 + (1 / t^2 - (1 + cos t) / (2 t sin t)) [e]x^2``, ``t = |e|``
    (identity at ``e = 0``; singular at ``t = pi``).
    """
    t = float(np.linalg.norm(e))
    E = skew(e)
    if t < 1e-6:
        return np.eye(3) + 0.5 * E + (1.0 / 12.0) * (E @ E)  # series of the coefficient: 1/12 + t^2/720
    coef = 1.0 / t**2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t))
    return np.eye(3) + 0.5 * E + coef * (E @ E)


@dataclass(frozen=True)
class Frame:
    """A point (and orientation) on the robot: a site, the mean of sites, or a body's origin.

    Build it with :meth:`Kinematics.site` or :meth:`Kinematics.body`. ``ids`` (k,) are MuJoCo ids;
    the orientation of a multi-site frame is that of its first site.
    """

    kind: str
    ids: tuple
    name: str


class Kinematics:
    """Forward kinematics of a :class:`~corl.mujoco.robot.Robot` in its task coordinates q.

    Parameters
    ----------
    robot : Robot
    """

    def __init__(self, robot: Robot) -> None:
        import mujoco

        self._mj = mujoco
        self.robot = robot
        self.model = robot.model
        self.data = mujoco.MjData(robot.model)
        nv = robot.model.nv
        self._jac_a, self._jac_b = np.zeros((3, nv)), np.zeros((3, nv))
        self._jac_rot = np.zeros((3, nv))
        self._slope = 1.0
        self._key: bytes | None = None  # q.tobytes() of the pose of the private data
        self._unit_ratios = bool(np.all(robot.ratios == 1.0))

    # ---------------------------------------------------------------- frames
    def site(self, *names: str) -> Frame:
        """Frame at a site, or at the mean of several sites (e.g. ``site("pad_l", "pad_r")``)."""
        if not names:
            raise InputError("site() needs at least one site name")
        return Frame("site", tuple(self.robot.id("site", n) for n in names), "+".join(names))

    def body(self, name: str) -> Frame:
        """Frame at the origin of body ``name``, with its orientation."""
        return Frame("body", (self.robot.id("body", name),), name)

    # ---------------------------------------------------------------- pose the private model
    def set_q(self, q: np.ndarray) -> None:
        """Pose the private model at ``q`` (Q,) and update its kinematics (nothing to do when it is
        already there: the stacked features of one time step pose it once)."""
        r = self.robot
        q = np.asarray(q, dtype=float)
        if q.shape != (r.dim,):
            r.check_q(q)  # raises with the expected layout
        key = q.tobytes()
        if key == self._key:
            return
        if not np.isfinite(q).all():
            r.check_q(q)  # raises: NaN or inf
        self._key = key
        d, J = self.data, r.num_joints
        d.qpos[r.qpos] = q[:J]
        if r.gripper is not None:
            angle = r.gripper.angle(q[J])
            d.qpos[r.gripper_qpos] = angle if self._unit_ratios else r.ratios * angle
            self._slope = r.gripper.dc_da(angle)
        self._mj.mj_kinematics(r.model, d)
        self._mj.mj_comPos(r.model, d)

    def task_columns(self, jac_full: np.ndarray) -> np.ndarray:
        """Columns (3, Q) of a Jacobian over all dofs (3, nv) in task coordinates (at the last q)."""
        r = self.robot
        J = r.num_joints
        jac = np.empty((jac_full.shape[0], r.dim))
        jac[:, :J] = jac_full[:, r.dof]
        if r.gripper is not None:  # chain rule through q_i = ratios_i a(c): sum_i ratios_i J_i / (dc/da)
            cols = jac_full[:, r.gripper_dof]
            jac[:, J] = (cols.sum(axis=1) if self._unit_ratios else (cols * r.ratios).sum(axis=1)) / self._slope
        return jac

    # ---------------------------------------------------------------- at the current pose
    def current_position(self, frame: Frame) -> np.ndarray:
        """p (3,) at the pose of the last :meth:`set_q`."""
        if frame.kind == "site":
            return self.data.site_xpos[list(frame.ids)].mean(axis=0)
        return self.data.xpos[frame.ids[0]].copy()

    def current_position_jacobian(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """p (3,) and Jp (3, Q) at the pose of the last :meth:`set_q`."""
        mj, m, d = self._mj, self.model, self.data
        if frame.kind == "site":
            mj.mj_jacSite(m, d, self._jac_a, None, int(frame.ids[0]))
            acc = self._jac_a
            if len(frame.ids) > 1:  # the mean of the sites' Jacobians
                acc = self._jac_a.copy()
                for k in frame.ids[1:]:
                    mj.mj_jacSite(m, d, self._jac_b, None, int(k))
                    acc += self._jac_b
                acc *= 1.0 / len(frame.ids)
        else:
            mj.mj_jacBody(m, d, self._jac_a, None, int(frame.ids[0]))
            acc = self._jac_a
        return self.current_position(frame), self.task_columns(acc)

    def current_rotation(self, frame: Frame) -> np.ndarray:
        """R (3, 3) at the pose of the last :meth:`set_q`."""
        mat = self.data.site_xmat if frame.kind == "site" else self.data.xmat
        return mat[frame.ids[0]].reshape(3, 3).copy()

    def current_rotation_jacobian(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """R (3, 3) and Jw (3, Q) at the pose of the last :meth:`set_q`."""
        if frame.kind == "site":
            self._mj.mj_jacSite(self.model, self.data, None, self._jac_rot, int(frame.ids[0]))
        else:
            self._mj.mj_jacBody(self.model, self.data, None, self._jac_rot, int(frame.ids[0]))
        return self.current_rotation(frame), self.task_columns(self._jac_rot)

    # ---------------------------------------------------------------- at a given q
    def position(self, q: np.ndarray, frame: Frame) -> np.ndarray:
        """World position p(q) (3,) of ``frame``."""
        self.set_q(q)
        return self.current_position(frame)

    def position_jacobian(self, q: np.ndarray, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """p(q) (3,) and dp/dq (3, Q)."""
        self.set_q(q)
        return self.current_position_jacobian(frame)

    def rotation(self, q: np.ndarray, frame: Frame) -> np.ndarray:
        """World orientation R(q) (3, 3) of ``frame``."""
        self.set_q(q)
        return self.current_rotation(frame)

    def rotation_jacobian(self, q: np.ndarray, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """R(q) (3, 3) and the angular-velocity Jacobian Jw (3, Q)."""
        self.set_q(q)
        return self.current_rotation_jacobian(frame)
