"""Track a joint reference with PD servos and gravity compensation (the policy of Sec. V-A).

Glossary
--------
q_ref, dq_ref  (N, Q) reference configurations at the control step and their velocities
u              (N, J + 1) or (N, J) servo set-points written to ``data.ctrl[actuators]``: the
               robot joints, then the gripper's driven angle
kp, kv         (J,) servo gains (Nm/rad, Nms/rad or N/m, Ns/m); effort (J,) the torque limits
tau            a servo's torque: ``kp (u - q) - kv dq``, clipped to its effort limit

The PD law is realised by MuJoCo position servos (:func:`add_servos`), whose damping the implicit
integrator (``implicitfast``) treats implicitly, so stiff gains stay stable at 500 Hz. The
reference velocity enters as a set-point lead ``u = q_ref + (kv / kp) dq_ref``, which makes the
servo torque exactly ``kp (q_ref - q) + kv (dq_ref - dq)``. Gravity and Coriolis forces of the
robot are cancelled by ``qfrc_applied = qfrc_bias`` on its dofs (as a real arm's controller does),
so the servos only see the tracking error and the contact forces.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from corl.errors import InputError
from corl.mujoco.parse import check_spec
from corl.mujoco.robot import Robot

__all__ = ["add_servo", "add_servos", "dense_reference", "PDController", "track"]


def add_servo(spec, joint: str, kp: float, kv: float, effort: float) -> None:
    """Add a position servo ``servo_<joint>`` on ``joint`` to ``spec`` (a mujoco.MjSpec).

    Its torque is ``kp (ctrl - q) - kv dq`` clipped to ``[-effort, effort]``; the set-point
    ``ctrl`` is unlimited. An unknown joint, one that is not a hinge or slide, or one with a servo
    already is refused now (not when the spec compiles).
    """
    check_spec(spec, "add_servo")
    _check_servo(spec, joint, kp, kv, effort)
    _add_servo(spec, joint, kp, kv, effort)


def _check_servo(spec, joint: str, kp: float, kv: float, effort: float) -> None:
    """Refuse bad gains, or a joint that ``spec`` lacks, that is not a hinge or slide, or that has a servo."""
    import mujoco

    if not (kp > 0 and kv >= 0 and effort > 0):
        raise InputError(f"servo on {joint!r} needs kp > 0, kv >= 0, effort > 0; got {kp}, {kv}, {effort}")
    found = spec.joint(joint) if isinstance(joint, str) and joint else None
    if found is None:
        names = [j.name for j in spec.joints if j.name]
        raise InputError(f"no joint {joint!r} in the spec (was it locked by load_spec?); its joints are {names}")
    if int(found.type) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
        raise InputError(f"joint {joint!r} is not a hinge or slide: a servo drives one position")
    if spec.actuator(f"servo_{joint}") is not None:
        raise InputError(f"joint {joint!r} has a servo already (servo_{joint}); add each servo once")


def _add_servo(spec, joint: str, kp: float, kv: float, effort: float) -> None:
    import mujoco

    act = spec.add_actuator(name=f"servo_{joint}", target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.gaintype = mujoco.mjtGain.mjGAIN_FIXED
    act.biastype = mujoco.mjtBias.mjBIAS_AFFINE
    act.gainprm[0] = kp
    act.biasprm[0:3] = [0.0, -kp, -kv]
    act.forcelimited = True
    act.forcerange = [-effort, effort]
    act.ctrllimited = False


def add_servos(spec, joints: Sequence[str], kp: Sequence[float], kv: Sequence[float],
               effort: Sequence[float]) -> None:
    """:func:`add_servo` on each of ``joints`` with its gain and limit (all (J,)); all or none."""
    joints = list(joints)
    for name, values in (("kp", kp), ("kv", kv), ("effort", effort)):
        if len(values) != len(joints):
            raise InputError(f"{name} has {len(values)} values, expected one per joint ({len(joints)})")
    if len(set(joints)) != len(joints):
        raise InputError(f"joints {joints} name a joint twice; add each servo once")
    check_spec(spec, "add_servos")
    servos = [(j, float(p), float(v), float(e)) for j, p, v, e in zip(joints, kp, kv, effort)]
    for servo in servos:  # check all before adding any
        _check_servo(spec, *servo)
    for servo in servos:
        _add_servo(spec, *servo)


def dense_reference(reference, duration: float, dt: float, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Sample a reference at the control rate.

    Parameters
    ----------
    reference : (N, Q) array at ``dt`` (a shorter array holds its last row), or a callable
        ``t -> (Q,)``.
    duration, dt : s.
    dim : Q.

    Returns
    -------
    q_ref : (K + 1, Q), dq_ref : (K + 1, Q) with K = round(duration / dt) (finite differences).
    """
    n = int(round(duration / dt)) + 1
    if callable(reference):
        q_ref = np.array([reference(k * dt) for k in range(n)], dtype=float)
    else:
        q_ref = np.asarray(reference, dtype=float)
        if q_ref.ndim != 2 or q_ref.shape[1] != dim:
            raise InputError(f"reference has shape {q_ref.shape}, expected (N, {dim}): one configuration q "
                             "per control step")
        if len(q_ref) < n:
            q_ref = np.vstack([q_ref, np.repeat(q_ref[-1:], n - len(q_ref), axis=0)])
        q_ref = q_ref[:n]
    if q_ref.shape[1:] != (dim,):
        raise InputError(f"the reference gives configurations of shape {q_ref.shape[1:]}, expected ({dim},)")
    if not np.all(np.isfinite(q_ref)):
        raise InputError("reference contains NaN or inf")
    dq_ref = np.gradient(q_ref, dt, axis=0) if n > 1 else np.zeros_like(q_ref)
    return q_ref, dq_ref


class PDController:
    """Set-points for a robot's servos and gravity compensation.

    Parameters
    ----------
    robot : Robot
    kp, kv : (J,) gains of the robot joints' servos (the same as in :func:`add_servos`); only
        their ratio, the set-point lead, is used here.
    actuators : names of the servos in q's order (robot joints, then the gripper's driven joint);
        default ``servo_<joint>`` as :func:`add_servos` names them.
    """

    def __init__(self, robot: Robot, kp: Sequence[float], kv: Sequence[float],
                 actuators: Sequence[str] | None = None) -> None:
        import mujoco

        kp, kv = np.asarray(kp, dtype=float), np.asarray(kv, dtype=float)
        J = robot.num_joints
        if kp.shape != (J,) or kv.shape != (J,) or np.any(kp <= 0):
            raise InputError(f"kp and kv need one value per robot joint ({J},), kp > 0")
        self.robot = robot
        self._lead = kv / kp
        self._comp_dofs = robot.dofs
        if actuators is None:
            actuators = [f"servo_{n}" for n in robot.joints] + ([f"servo_{robot.gripper.joints[0]}"] if robot.gripper else [])
        ids = [mujoco.mj_name2id(robot.model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in actuators]
        missing = [a for a, k in zip(actuators, ids) if k < 0]
        if missing:
            raise InputError(f"no actuator named {missing[0]!r}; add the servos with corl.mujoco.add_servos")
        self.actuators = np.array(ids, dtype=int)
        # all actuators in q's order: write data.ctrl whole (cheaper than an index)
        self._whole = bool(len(ids) == robot.model.nu and np.array_equal(ids, np.arange(len(ids))))
        self._ctrl_slice = _as_slice(self.actuators, ordered=True)
        self._comp_slice = _as_slice(self._comp_dofs, ordered=False)

    def setpoints(self, q_ref: np.ndarray, dq_ref: np.ndarray) -> np.ndarray:
        """Servo set-points u (N, J [+1]) for a reference (N, Q): joint lead, gripper angle."""
        J = self.robot.num_joints
        u = np.empty((q_ref.shape[0], len(self.actuators)))
        u[:, :J] = q_ref[:, :J] + self._lead * dq_ref[:, :J]
        if self.robot.gripper is not None:
            u[:, J] = self.robot.gripper.angle(q_ref[:, J])
        return u

    def apply(self, data, u: np.ndarray) -> None:
        """Write one row of set-points (J [+1],) to ``data.ctrl``."""
        if self._whole:
            data.ctrl[:] = u
        else:
            data.ctrl[self.actuators] = u

    def compensate(self, data) -> None:
        """Cancel gravity and Coriolis forces on the robot's dofs (``qfrc_applied = qfrc_bias``)."""
        data.qfrc_applied[self._comp_dofs] = data.qfrc_bias[self._comp_dofs]

    def _views(self, data) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Views ``(ctrl, qfrc_applied, qfrc_bias)`` of ``data`` such that ``ctrl[:] = u_k`` is
        :meth:`apply` and ``applied[:] = bias`` is :meth:`compensate`, or None when a subclass
        overrides either or the actuators or dofs are not a contiguous range."""
        own = all(getattr(type(self), name) is getattr(PDController, name) and name not in vars(self)
                  for name in ("apply", "compensate"))
        if not own or self._ctrl_slice is None or self._comp_slice is None:
            return None
        comp = self._comp_slice
        return data.ctrl[self._ctrl_slice], data.qfrc_applied[comp], data.qfrc_bias[comp]

    def initialise(self, data, q0: np.ndarray) -> None:
        """Put the robot at ``q0`` (Q,), at rest."""
        self.robot.write(data, q0)
        data.qvel[:] = 0.0


def _as_slice(ids: np.ndarray, ordered: bool) -> slice | None:
    """``ids`` (n,) as the slice of the same entries, or None. ``ordered``: ``ids`` must run up one
    by one (it pairs values to entries); otherwise the same set of entries will do (an entry
    copied onto itself, e.g. ``qfrc_applied[dofs] = qfrc_bias[dofs]``, ignores the order)."""
    ids = np.asarray(ids, dtype=int)
    if ids.size == 0:
        return None
    run = np.arange(ids.min(), ids.min() + ids.size)
    same = np.array_equal(ids, run) if ordered else np.array_equal(np.unique(ids), run)
    return slice(int(run[0]), int(run[-1]) + 1) if same else None


def track(robot: Robot, controller: PDController, reference, duration: float, *, data=None,
          prepare: Callable | None = None, on_step: Callable | None = None):
    """Simulate tracking ``reference`` from rest at its first configuration.

    Each control step (the simulation step) sets the set-points, cancels gravity, steps, and calls
    ``on_step(k, data)`` (also at k = 0, before the first step). A :class:`PDController` whose
    actuators and dofs are contiguous ranges is not called each step: its writes go through views of
    ``data`` bound once (the same values); a subclass that overrides ``apply`` or ``compensate`` is.
    ``on_step`` runs 2500 times in a 5 s trial at 500 Hz: bind what it reads (``qpos = data.qpos``)
    outside it, copy into preallocated arrays, and leave what can wait until after the trial.

    Parameters
    ----------
    robot, controller : the robot and its :class:`PDController`.
    reference : (N, Q) at the model's timestep, or callable ``t -> (Q,)``; see :func:`dense_reference`.
    duration : s.
    data : a ``mujoco.MjData`` to reuse (it is reset), optional.
    prepare : ``prepare(data)`` after the robot is placed, before the first ``mj_forward``
        (e.g. to activate an equality or place an object).
    on_step : ``on_step(k, data)``: log, switch a latch, stop nothing.

    Returns
    -------
    data : the final mujoco.MjData; q_ref : (K + 1, Q) the reference as tracked.
    """
    import mujoco

    model = robot.model
    dt = model.opt.timestep
    if data is None:
        data = mujoco.MjData(model)
    else:
        mujoco.mj_resetData(model, data)
    q_ref, dq_ref = dense_reference(reference, duration, dt, robot.dim)
    u = controller.setpoints(q_ref, dq_ref)
    controller.initialise(data, q_ref[0])
    if prepare is not None:
        prepare(data)
    controller.apply(data, u[0])
    mujoco.mj_forward(model, data)
    controller.compensate(data)  # so the first logged sensor reading already sees a supported arm
    mujoco.mj_forward(model, data)
    views = controller._views(data) if isinstance(controller, PDController) else None
    if on_step is not None:
        on_step(0, data)
    if views is None:  # a controller that writes its own way: call it each step
        for k in range(1, len(q_ref)):
            controller.apply(data, u[k])
            controller.compensate(data)
            mujoco.mj_step(model, data)
            if on_step is not None:
                on_step(k, data)
        return data, q_ref
    # The same writes as apply and compensate, through views bound once: about 0.4 us a step
    # besides mj_step (10-15 us on the door), where the method calls and fancy indexing cost 4 us.
    ctrl, applied, bias = views
    step = mujoco.mj_step
    for k in range(1, len(q_ref)):
        ctrl[:] = u[k]
        applied[:] = bias
        step(model, data)
        if on_step is not None:
            on_step(k, data)
    return data, q_ref
