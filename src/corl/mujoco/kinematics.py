"""Forward kinematics of sites and bodies in task coordinates, their Jacobians, rotation errors.

Glossary
--------
q          (Q,) task configuration (see :mod:`corl.mujoco.robot`)
frame      a site, the mean of several sites (e.g. two fingertip pads), a body's origin, or the
           mean of points fixed on bodies (:meth:`Kinematics.points`, e.g. where a recording touched)
p(q)       (3,) world position of a frame; ``Jp`` (3, Q) its Jacobian dp/dq
R(q)       (3, 3) world orientation of a frame (columns: its axes); ``Jw`` (3, Q) the angular
           velocity Jacobian: ``omega = Jw dq/dt``, ``dR/dt = [omega]x R``
e          (3,) rotation error ``log(R_target R^T)`` as an axis-angle vector: the rotation (world
           frame) that takes R onto R_target
theta      (m,) the dofs q drives (``robot.dofs``: arm, then gripper joints); ``T`` (m, Q) the
           task map ``dtheta/dq`` (identity on the arm, ``ratios / slope`` in the gripper column)
Hp         (3, Q, Q) ``d2p/dq2``; ``W`` (3, Q, Q) ``W[:, i, j] = dJw[:, j]/dq_i`` (not symmetric)
omega_a    (3,) column a of Jw: the world axis of hinge a (zero for a slide); ``v_a`` column a of Jp

Second derivatives (exact, from the Jacobians of one pose: no extra forward kinematics). Dof a
*precedes* dof b when a < b and both lie on the chain to the frame (MuJoCo numbers a parent's dofs
before its children's, and applies a body's joints in order). Turning a hinge a turns everything
after it rigidly, so ``d v_b / d theta_a = omega_a x v_b`` and ``d omega_b / d theta_a = omega_a x
omega_b`` when a precedes (or is) b, and 0 when b precedes a (its axis does not move). Hence

    d2p / dtheta_a dtheta_b = omega_min(a,b) x v_max(a,b)                    (point Hessian)
    W_ab = d omega_b / dtheta_a = omega_a x omega_b  (a < b), else 0

(zero for a slide a: ``omega_a = 0``; a dof off the chain has zero columns). In q, with
``theta(q)``, ``T^T (.) T`` plus ``dy/dc * a''(c) / a'(c)`` at (c, c), ``a''/a' = -slope'(a) / slope^2``.

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

__all__ = ["Frame", "FrameJacobians", "Kinematics", "angular_jacobian_derivative", "cross_table", "point_hessian",
           "rotation_error", "rotation_error_jacobian", "rotation_error_second", "skew"]


def skew(v: np.ndarray) -> np.ndarray:
    """``[v]x`` (3, 3), the cross-product matrix of ``v`` (3,)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rotation_error(r_target: np.ndarray, r_current: np.ndarray) -> np.ndarray:
    """Axis-angle vector ``e = log(R_target R_current^T)`` (3,) that rotates ``r_current`` (3, 3)
    onto ``r_target`` (3, 3) in the world frame; ``|e|`` is the angle (rad) between them."""
    r_err = r_target @ r_current.T
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r_err.tolist()  # Python floats: cheaper than numpy scalars
    cos = min(max((r00 + r11 + r22 - 1.0) / 2.0, -1.0), 1.0)
    angle = np.arccos(cos)
    axis = np.array([r21 - r12, r02 - r20, r10 - r01])
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


def _coefficients(t: float) -> tuple[float, float]:
    """``c(t) = 1/t^2 - (1 + cos t) / (2 t sin t)`` of :func:`rotation_error_jacobian` and ``c'(t) / t``.

    Below t = 0.2 their series (``1/12 + t^2/720 + t^4/30240``, ``1/360 + t^2/7560 + t^4/201600``;
    truncation < 1e-11 relative there): the closed forms lose ``eps / t^4`` to cancellation.
    """
    if t < 0.2:
        t2 = t * t
        return 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0, 1.0 / 360.0 + t2 / 7560.0 + t2 * t2 / 201600.0
    s, co = np.sin(t), np.cos(t)
    c = 1.0 / t**2 - (1.0 + co) / (2.0 * t * s)
    return c, -2.0 / t**4 + (1.0 + co) / (2.0 * t**3 * s) + 1.0 / (2.0 * t**2 * (1.0 - co))


_LEVI_CIVITA = np.zeros((3, 9))  # row j, column 3 i + k: eps_ijk, so [u]x = (u @ _LEVI_CIVITA).reshape(3, 3)
for _i, _j, _k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
    _LEVI_CIVITA[_j, 3 * _i + _k], _LEVI_CIVITA[_k, 3 * _i + _j] = 1.0, -1.0


def cross_table(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """All cross products of columns: ``C[..., :, a, b] = u[..., :, a] x v[..., :, b]``.

    u : (..., 3, m); v : (..., 3, k). Returns (..., 3, m, k). Two matrix products: the
    cross-product matrices ``[u_a]x`` (..., m, 3, 3) from the Levi-Civita symbol, times v.
    """
    skews = (np.swapaxes(u, -1, -2) @ _LEVI_CIVITA).reshape(u.shape[:-2] + (u.shape[-1], 3, 3))
    return np.swapaxes(skews @ v[..., None, :, :], -3, -2)  # (..., m, 3, k) -> (..., 3, m, k)


def point_hessian(jacp: np.ndarray, jacr: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """``d2p / dtheta_a dtheta_b = omega_min(a,b) x v_max(a,b)`` (3, m, m) of a point (glossary).

    jacp, jacr : (3, m) or (s, 3, m) its position and angular Jacobians over the dofs ``dofs`` (m,)
    (MuJoCo dof addresses: the order decides which dof precedes); several points are averaged.
    """
    C = cross_table(jacr, jacp)  # C[:, a, b] = omega_a x v_b
    H = np.where(dofs[:, None] <= dofs[None, :], C, np.swapaxes(C, -1, -2))
    return H if H.ndim == 3 else H.mean(axis=0)


def angular_jacobian_derivative(jacr: np.ndarray, dofs: np.ndarray) -> np.ndarray:
    """``W[:, a, b] = d omega_b / dtheta_a`` (3, m, m): ``omega_a x omega_b`` when dof a precedes b, else 0.

    jacr : (3, m) angular Jacobian over the dofs ``dofs`` (m,) (MuJoCo dof addresses).
    """
    C = cross_table(jacr, jacr)
    return np.where(dofs[:, None] < dofs[None, :], C, 0.0)


def rotation_error_second(e: np.ndarray, jw: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives of ``-e`` (:func:`rotation_error`) over the dofs theta.

    With ``A = J_r^{-1}(e)`` (:func:`rotation_error_jacobian`), ``d(-e)/dtheta = A Jw`` and
    ``de/dtheta_a = v_a = -A omega_a``, so ``K[:, a, b] = d(A omega_b)/dtheta_a = dA[v_a] omega_b + A W_ab``
    with the directional derivative of ``A = I + E/2 + c(t) E^2`` (E = [e]x, t = |e|)::

        dA[v] omega = v x omega / 2 + c (v x (e x omega) + e x (v x omega)) + (c'(t)/t) (e . v) E^2 omega

    e : (3,) the error; jw : (3, m) Jw over theta; W : (3, m, m) :func:`angular_jacobian_derivative`.
    Returns ``(A Jw (3, m), K (3, m, m))``; K is symmetric (a Hessian). Singular at t = pi.
    """
    A = rotation_error_jacobian(e)
    E = skew(e)
    c, c_t = _coefficients(float(np.linalg.norm(e)))
    V = -A @ jw  # v_a = de/dtheta_a
    C = cross_table(V, jw)  # v_a x omega_b
    K = 0.5 * C + c * (cross_table(V, E @ jw) + (E @ C.reshape(3, -1)).reshape(C.shape))
    K += c_t * (e @ V)[None, :, None] * (E @ (E @ jw))[:, None, :]
    K += (A @ W.reshape(3, -1)).reshape(W.shape)
    return A @ jw, K


class FrameJacobians:
    """A frame's Jacobians over the dofs theta at one pose: its first and second derivatives in q.

    A snapshot (its arrays are its own), so second derivatives can be formed later from the pose of
    one ``mj_kinematics``, after the private data has moved on. Build it with
    :meth:`Kinematics.current_jacobians`.

    Attributes
    ----------
    jacp, jacr : (s, 3, m) position and angular Jacobians of the frame's s sites (1 for a body)
    dofs : (m,) their MuJoCo dof addresses (``robot.dofs``: the J arm joints, then the gripper's)
    """

    __slots__ = ("jacp", "jacr", "dofs", "_J", "_gripper", "_ratios", "_angle", "_slope")

    def __init__(self, jacp, jacr, dofs, num_joints, gripper=None, ratios=None, angle=0.0, slope=1.0) -> None:
        self.jacp, self.jacr, self.dofs, self._J = jacp, jacr, dofs, num_joints
        self._gripper, self._ratios, self._angle, self._slope = gripper, ratios, angle, slope

    @property
    def task_map(self) -> np.ndarray:
        """T = dtheta/dq (m, Q): identity on the arm, ``ratios / slope`` in the gripper column."""
        J, m = self._J, self.dofs.shape[0]
        T = np.zeros((m, J + (self._gripper is not None)))
        T[np.arange(J), np.arange(J)] = 1.0
        if self._gripper is not None:
            T[J:, J] = self._ratios / self._slope
        return T

    def in_q(self, jac: np.ndarray) -> np.ndarray:
        """``dy/dq = dy/dtheta T`` (d, Q) of ``dy/dtheta`` (d, m); the gripper column
        ``sum_i ratios_i dy/dtheta_i / slope`` (the chain rule through ``theta_i = ratios_i a(c)``)."""
        J = self._J
        if self._gripper is None:
            return jac.copy()
        out = np.empty((jac.shape[0], J + 1))
        out[:, :J] = jac[:, :J]
        out[:, J] = (jac[:, J:] * self._ratios).sum(axis=1) / self._slope
        return out

    def position_jacobian(self) -> np.ndarray:
        """Jp (3, Q): the mean of the sites' Jacobians, in q."""
        s = self.jacp.shape[0]
        return self.in_q(self.jacp[0] if s == 1 else self.jacp.sum(axis=0) * (1.0 / s))

    def rotation_jacobian(self) -> np.ndarray:
        """Jw (3, Q) of the first site, in q."""
        return self.in_q(self.jacr[0])

    def position_hessian(self, jp: np.ndarray) -> np.ndarray:
        """Hp (3, Q, Q) = d2p/dq2 (the mean over the sites), given Jp (3, Q) of this pose."""
        return self.to_task(point_hessian(self.jacp, self.jacr, self.dofs), jp)

    def angular_derivative(self) -> np.ndarray:
        """W (3, m, m) = d omega_b / dtheta_a over the dofs (first site)."""
        return angular_jacobian_derivative(self.jacr[0], self.dofs)

    def to_task(self, K: np.ndarray, jac: np.ndarray) -> np.ndarray:
        """``d2y/dq_i dq_j`` (d, Q, Q) from ``K[:, a, b] = d(dy/dtheta_b)/dtheta_a`` (d, m, m) and
        ``dy/dq`` (d, Q): ``T^T K T``, plus ``dy/dc a''/a'`` at (c, c) (the gripper's ``theta(c)``)."""
        T = self.task_map
        out = T.T @ K @ T
        if self._gripper is not None:
            out[:, self._J, self._J] += jac[:, self._J] * self.gripper_curvature()
        return out

    def gripper_curvature(self) -> float:
        """``a''(c) / a'(c) = -slope'(a) / slope^2``; slope' by a central difference of
        :meth:`Gripper.dc_da` (a scalar function: no kinematics), 0 for the default constant slope."""
        g = self._gripper
        if g is None or g.slope is None:
            return 0.0
        a = float(self._angle)
        h = 1e-5 * (1.0 + abs(a))
        ds = (float(g.dc_da(a + h)) - float(g.dc_da(a - h))) / (2.0 * h)
        return -ds / float(self._slope) ** 2


@dataclass(frozen=True)
class Frame:
    """A point (and orientation) on the robot: a site, the mean of sites, a body's origin, or the mean
    of points fixed on bodies.

    Build it with :meth:`Kinematics.site`, :meth:`Kinematics.body` or :meth:`Kinematics.points`.
    ``ids`` (k,) are MuJoCo ids; the orientation of a multi-site frame is that of its first site (of a
    ``"point"`` frame, its first body's). ``offsets`` (k, 3): each point in its body's frame
    (``"point"`` frames only).
    """

    kind: str
    ids: tuple
    name: str
    offsets: tuple = ()


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
        self._slope, self._angle = 1.0, 0.0
        self._key: bytes | None = None  # q.tobytes() of the pose of the private data
        self._unit_ratios = bool(np.all(robot.ratios == 1.0))
        self._dofs = robot.dofs.astype(np.int64)
        self._buffer = np.zeros((2, 3, nv))  # jacp, jacr of one site (views of it are contiguous)

    # ---------------------------------------------------------------- frames
    def site(self, *names: str) -> Frame:
        """Frame at a site, or at the mean of several sites (e.g. ``site("pad_l", "pad_r")``)."""
        if not names:
            raise InputError("site() needs at least one site name")
        return Frame("site", tuple(self.robot.id("site", n) for n in names), "+".join(names))

    def body(self, name: str) -> Frame:
        """Frame at the origin of body ``name``, with its orientation."""
        return Frame("body", (self.robot.id("body", name),), name)

    def points(self, bodies, offsets, name: str = "") -> Frame:
        """Frame at the mean of points fixed on bodies: ``bodies`` (k,) names, ``offsets`` (k, 3) each
        point in its body's frame (m); oriented as the first body (a site the model does not have)."""
        offsets = np.asarray(offsets, dtype=float).reshape(-1, 3) if len(bodies) else np.zeros((0, 3))
        if not len(bodies) or offsets.shape[0] != len(bodies) or not np.all(np.isfinite(offsets)):
            raise InputError(f"points() needs one finite offset (3,) per body, got {len(bodies)} bodies and offsets "
                             f"of shape {offsets.shape}")
        ids = tuple(self.robot.id("body", b) for b in bodies)
        return Frame("point", ids, name or "+".join(bodies), tuple(tuple(float(v) for v in o) for o in offsets))

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
            self._slope, self._angle = r.gripper.dc_da(angle), angle
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
    def current_jacobians(self, frame: Frame) -> FrameJacobians:
        """The frame's Jacobians over the dofs q drives at the pose of the last :meth:`set_q`: one
        ``mj_jacSite`` / ``mj_jacBody`` per site, both halves (position and angle) at once."""
        mj, m, d, buf = self._mj, self.model, self.data, self._buffer
        jac = mj.mj_jacSite if frame.kind == "site" else mj.mj_jacBody
        out = np.empty((len(frame.ids), 2, 3, self._dofs.shape[0]))
        for s, k in enumerate(frame.ids):
            if frame.kind == "point":  # the Jacobian of a world point moving with body k
                mj.mj_jac(m, d, buf[0], buf[1], self._point(frame, s), int(k))
            else:
                jac(m, d, buf[0], buf[1], int(k))
            out[s] = buf[:, :, self._dofs]
        r = self.robot
        return FrameJacobians(out[:, 0], out[:, 1], self._dofs, r.num_joints, r.gripper, r.ratios, self._angle,
                              self._slope)

    def current_position(self, frame: Frame) -> np.ndarray:
        """p (3,) at the pose of the last :meth:`set_q`."""
        if frame.kind == "site":
            return self.data.site_xpos[list(frame.ids)].mean(axis=0)
        if frame.kind == "point":
            return np.mean([self._point(frame, s) for s in range(len(frame.ids))], axis=0)
        return self.data.xpos[frame.ids[0]].copy()

    def _point(self, frame: Frame, s: int) -> np.ndarray:
        """World position (3,) of point s of a ``"point"`` frame at the current pose."""
        k = frame.ids[s]
        return self.data.xpos[k] + self.data.xmat[k].reshape(3, 3) @ np.asarray(frame.offsets[s])

    def current_position_jacobian(self, frame: Frame) -> tuple[np.ndarray, np.ndarray]:
        """p (3,) and Jp (3, Q) at the pose of the last :meth:`set_q`."""
        mj, m, d = self._mj, self.model, self.data
        if frame.kind == "point":
            return self.current_position(frame), self.current_jacobians(frame).position_jacobian()
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
        if frame.kind == "point":
            return self.current_rotation(frame), self.current_jacobians(frame).rotation_jacobian()
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

    def position_hessian(self, q: np.ndarray, frame: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """p(q) (3,), dp/dq (3, Q) and d2p/dq2 (3, Q, Q) (exact, see the module docstring)."""
        self.set_q(q)
        jacobians = self.current_jacobians(frame)
        jp = jacobians.position_jacobian()
        return self.current_position(frame), jp, jacobians.position_hessian(jp)

    def rotation_jacobian_derivative(self, q: np.ndarray, frame: Frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """R(q) (3, 3), Jw (3, Q) and ``W[:, i, j] = dJw[:, j]/dq_i`` (3, Q, Q) (not symmetric)."""
        self.set_q(q)
        jacobians = self.current_jacobians(frame)
        jw = jacobians.rotation_jacobian()
        return self.current_rotation(frame), jw, jacobians.to_task(jacobians.angular_derivative(), jw)
