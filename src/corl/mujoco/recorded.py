"""A whole CORL task from a scene, a recorded demonstration, an object's name and a success test.

Glossary
--------
contacts    what the replay of the recording found (:func:`corl.mujoco.find_contacts`): per contact
            interval i the robot's contact point (points fixed on its touching bodies), the point
            ``p0_i`` (3,) it touched on the object and the normal ``n_i``, both in the object's frame
D_i         (3, m_i) orthonormal directions on the object's surface theta moves the contact along:
            the contact's two tangent directions, or the object axes a user names, projected onto
            the tangent plane
theta       (m,) = (theta_1, ..., theta_I): ``theta_i = D_i^T p_i``, the contact point's coordinates
            along D_i in the object's frame (m); the demonstration's is ``D_i^T p0_i``; with
            ``grip_bounds`` one more: the gripper's value while it holds (its recorded closed value)
p_i(theta)  ``p0_i + D_i (theta_i - D_i^T p0_i)``: the point on the object theta names
t_k         instants every ``spacing`` s of each interval, from ``approach`` s before it starts; with
            ``tolerance`` only those between which the targets (and the gripper's value)
            move within ``tolerance`` m of a straight line in time (the first contact instant kept)
d_ik        (3,) where the robot's contact point was at t_k relative to p0_i, in the object's frame
            (zero in contact up to the replay's millimetres; the approach above the surface before)
h(w, theta) Eq. 6 at every t_k: ``phi(xi(w, t_k)) = x_o(t_k) + R_o(t_k) (p_i(theta_i) + d_ik)``, the
            object's pose ``(x_o, R_o)`` as in the replay; with ``hold_orientation`` the touching
            body keeps its demonstrated orientation relative to the object (``orientation_weight``
            m/rad), with a gripper the gripper coordinate keeps its recorded value; and the start
            configuration is the recording's
J(w)        squared joint accelerations (Eq. 9) of a cubic B-spline over the recording's duration
w0          the B-spline fitted to the recording (least squares), projected onto h(., theta0) = 0
R, S        ``return_(log)`` and ``success(log)``, the user's, on the log of a simulated rollout
            (:meth:`RecordedTask.run`: the robot's servos track the reference)
"""

from __future__ import annotations

import copy
from functools import cached_property
from typing import Callable, Sequence

import numpy as np

from corl.errors import InputError
from corl.mujoco.control import PDController, track
from corl.mujoco.demo import project_demonstration
from corl.mujoco.features import coordinate_feature, orientation_feature, position_feature, stack
from corl.mujoco.forces import ContactPairs
from corl.mujoco.kinematics import Kinematics
from corl.mujoco.recording import Contacts, Recording, find_contacts, load_recording, subtree
from corl.mujoco.robot import Robot
from corl.problem import Bounds, Demonstration, Outcome
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature

__all__ = ["RecordedTask", "task_from_recording", "servo_controller"]

AXES = {"x": 0, "y": 1, "z": 2}


def servo_controller(robot: Robot) -> PDController:
    """A :class:`PDController` whose gains are read from the servos ``servo_<joint>`` of the model
    (:func:`corl.mujoco.add_servos` names them so)."""
    import mujoco

    model, kp, kv = robot.model, [], []
    for joint in robot.joints:
        k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, f"servo_{joint}")
        if k < 0:
            raise InputError(f"no servo 'servo_{joint}' in the scene; add them with corl.mujoco.add_servos or pass "
                             "controller=")
        kp.append(float(model.actuator_gainprm[k, 0]))
        kv.append(float(-model.actuator_biasprm[k, 2]))
    return PDController(robot, kp, kv)


def _directions(names, normal: np.ndarray, object: str) -> tuple[np.ndarray, list]:
    """D (3, m) and labels: the named object axes (or 3-vectors) on the tangent plane of ``normal``;
    by default the two object axes closest to it, made orthonormal."""
    plane = np.eye(3) - np.outer(normal, normal)
    if names is None:
        order = np.argsort(-np.linalg.norm(plane, axis=0))[:2]
        names = sorted("xyz"[i] for i in order)
    columns, labels = [], []
    for d in names:
        if isinstance(d, str):
            sign, axis = (-1.0, d[1:]) if d.startswith("-") else (1.0, d.lstrip("+"))
            if axis not in AXES:
                raise InputError(f"direction {d!r}: name an axis of '{object}' (x, y, z, -x, ...) or give a 3-vector")
            v, label = sign * np.eye(3)[AXES[axis]], d
        else:
            v = np.asarray(d, dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)) or not np.linalg.norm(v) > 0:
                raise InputError(f"direction {d!r}: give an axis name or a non-zero 3-vector in the object's frame")
            v, label = v / np.linalg.norm(v), np.array2string(v, precision=2)
        for c in columns:  # Gram-Schmidt: theta's coordinates are independent
            v = v - (v @ c) * c
        t = plane @ v
        if not np.linalg.norm(t) > 0.5:
            raise InputError(f"direction {label} of '{object}' is (nearly) the contact's normal or a direction given "
                             "before; theta moves the contact along the surface: name a tangent direction")
        columns.append(t / np.linalg.norm(t))
        labels.append(f"contact point along {label} of '{object}' (m)")
    return np.column_stack(columns), labels


class RecordedTask:
    """A task derived from a recorded demonstration (see the module glossary); every member of the
    task protocol (:class:`corl.problem.Task`) can be overridden in a subclass.

    Build it with :func:`task_from_recording`. Attributes: ``robot``, ``kin``, ``contacts``
    (:class:`~corl.mujoco.Contacts`), ``spline``, ``frames`` (the robot's contact point per
    interval), ``directions`` (D_i), ``times`` (t_k per interval), ``demo_report`` (after
    :meth:`demonstration`).
    """

    w_bounds = None

    def __init__(self, robot: Robot, contacts: Contacts, return_: Callable, success: Callable, *,
                 name: str | None = None, directions=None, theta_bounds: Bounds | None = None,
                 hold_orientation: bool = False, orientation_weight: float = 0.3, approach: float = 0.4,
                 spacing: float = 0.1, control_points: int | None = None, controller: PDController | None = None,
                 settings=None, grip_bounds: tuple[float, float] | None = None,
                 tolerance: float | None = None) -> None:
        if not (callable(return_) and callable(success)):
            raise InputError("return_ and success must be callables log -> number and log -> bool")
        if not (spacing > 0 and approach >= 0 and orientation_weight > 0):
            raise InputError(f"spacing ({spacing}) and orientation_weight ({orientation_weight}) must be positive, "
                             f"approach ({approach}) not negative")
        if tolerance is not None and not tolerance > 0:
            raise InputError(f"tolerance ({tolerance}) must be a positive distance (m), or None for every instant")
        self.robot, self.contacts, self._return, self._success = robot, contacts, return_, success
        self.name = name or f"{contacts.object}_from_recording"
        self.kin = Kinematics(robot)
        self.duration = float(contacts.times[-1])
        P = control_points or max(8, int(round(16 * self.duration)))
        self.spline = BSpline(P, robot.dim, duration=self.duration)
        self._acceleration = acceleration_feature(self.spline, 100)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])
        self.hold_orientation, self.orientation_weight = bool(hold_orientation), float(orientation_weight)
        self.frames, self.directions, self.times, labels = [], [], [], []
        for i, iv in enumerate(contacts.intervals):
            self.frames.append(self.kin.points(iv.bodies, iv.offsets, name=f"contact {i}"))
            D, lab = _directions(directions, iv.normal, contacts.object)
            self.directions.append(D)
            labels += lab if len(contacts.intervals) == 1 else [f"interval {i}: {x}" for x in lab]
            k = np.arange(-np.floor(approach / spacing + 1e-9), np.floor((iv.end - iv.start) / spacing + 1e-9) + 1)
            t = iv.start + spacing * k
            self.times.append(t[(t > 1e-9) & (t <= self.duration + 1e-9)])
        self.theta0 = np.concatenate([D.T @ iv.point for D, iv in zip(self.directions, contacts.intervals)])
        bounds = self._geometric_bounds()
        self.joint_names = tuple(robot.joints) + (("gripper",) if robot.gripper else ())
        self._targets = [self._instants(i) for i in range(len(contacts.intervals))]
        if tolerance is not None:
            for i, iv in enumerate(contacts.intervals):
                keep = pinned_instants(self._targets[i], self._theta0_of(i), iv.start, float(tolerance))
                self._targets[i] = [self._targets[i][k] for k in keep]
                self.times[i] = self.times[i][keep]
        self._first = [next(k for k, x in enumerate(xs) if x[0] >= iv.start - 1e-9)  # each one's first contact
                       for xs, iv in zip(self._targets, contacts.intervals)]
        self._closed = [[False] * len(x) for x in self._targets]  # instants whose gripper value is theta's
        if grip_bounds is not None:
            bounds = self._grip_theta(grip_bounds, bounds)
            labels.append("gripper while it holds (the gripper coordinate)")
        self.theta_labels = tuple(labels)
        self.theta_bounds = theta_bounds if theta_bounds is not None else bounds
        self._controller, self._settings = controller, settings
        self._problems: dict = {}
        self.demo_report = None

    def _theta0_of(self, i: int) -> np.ndarray:
        """The demonstration's theta_i (interval i's contact coordinates)."""
        start = sum(D.shape[1] for D in self.directions[:i])
        return self.theta0[start:start + self.directions[i].shape[1]]

    def _geometric_bounds(self) -> Bounds:
        """Each theta coordinate between the object's extremes along its direction (its geoms' boxes)."""
        spans = [self.contacts.extent @ D for D in self.directions]
        lower = np.concatenate([s.min(axis=0) for s in spans])
        upper = np.concatenate([s.max(axis=0) for s in spans])
        return Bounds(lower, upper)

    def _grip_theta(self, grip_bounds, bounds: Bounds) -> Bounds:
        """theta's last coordinate: the gripper value at the instants it holds the value it has at the
        end of the first contact (within 2 % of ``grip_bounds``' width); bounds ``grip_bounds``."""
        if self.robot.gripper is None:
            raise InputError("grip_bounds needs a robot with a gripper (its coordinate is q's last column)")
        lower, upper = (float(b) for b in grip_bounds)
        if not lower < upper:
            raise InputError(f"grip_bounds ({lower}, {upper}): the lower bound must be below the upper")
        closed, tol = self._targets[0][-1][4], 0.02 * (upper - lower)
        self._closed = [[abs(x[4] - closed) <= tol for x in instants] for instants in self._targets]
        self.theta0 = np.append(self.theta0, closed)
        return Bounds(np.append(bounds.lower, lower), np.append(bounds.upper, upper))

    def _instants(self, i: int) -> list:
        """Per t_k of interval i: (t_k, c_k (3,), M_k (3, m_i), R_k (3, 3), gripper value) with the
        contact target ``c_k + M_k theta_i`` and the body's orientation target R_k."""
        iv, D, c = self.contacts.intervals[i], self.directions[i], self.contacts
        out = []
        for t in self.times[i]:
            x, R, bodies = c.poses(float(t), iv.bodies)
            robot_point = np.mean([xb + Rb @ o for (xb, Rb), o in zip(bodies, iv.offsets)], axis=0)
            d = R.T @ (robot_point - x) - iv.point
            base = x + R @ (iv.point - D @ (D.T @ iv.point) + d)
            grip = c.q[c.step(float(t)), -1]
            out.append((float(t), base, R @ D, bodies[0][1], float(grip)))
        return out

    # -- Eq. 6-9 -----------------------------------------------------------------------------------
    def method_settings(self):
        """The ``settings`` given to :func:`task_from_recording` (a :class:`corl.settings.MethodSettings`)."""
        return self._settings

    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta) -> TrajectoryProblem:
        """J (Eq. 9) under h(., theta) (Eq. 6) as features, cached per theta."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        key = theta.tobytes()
        if key not in self._problems:
            start = self.contacts.q[0]
            eqs = [configuration_feature(self.spline, 0.0, start)]
            offset = 0
            for i, instants in enumerate(self._targets):
                m = self.directions[i].shape[1]
                th = theta[offset:offset + m]
                offset += m
                for (t, base, M, R, grip), closed in zip(instants, self._closed[i]):
                    grip = theta[-1] if closed else grip
                    parts, target = [position_feature(self.kin, self.frames[i])], [base + M @ th]
                    if self.hold_orientation:
                        parts.append(orientation_feature(self.kin, self.frames[i], R, weight=self.orientation_weight))
                        target.append(np.zeros(3))
                    if self.robot.gripper is not None:
                        parts.append(coordinate_feature(self.robot.dim, self.robot.dim - 1))
                        target.append([grip])
                    eqs.append(TaskSpaceFeature(self.spline, stack(*parts), [t], np.concatenate(target)))
            if len(self._problems) > 64:
                self._problems.clear()
            self._problems[key] = TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=eqs)
        return self._problems[key]

    def constraint(self, w, theta):
        return self.trajectory_problem(theta).equalities(w)

    def theta_of(self, w) -> np.ndarray:
        """theta (m,) of ``w`` by forward kinematics at each interval's first contact instant."""
        out = []
        for i, instants in enumerate(self._targets):
            t, base, M, _, _ = instants[self._first[i]]
            p = self.kin.position(self.spline.positions(w, [t])[0], self.frames[i])
            out.append(M.T @ (p - base))  # M = R_o D has orthonormal columns
        if any(any(c) for c in self._closed):
            i = next(i for i, c in enumerate(self._closed) if any(c))
            t = self._targets[i][self._closed[i].index(True)][0]
            out.append(self.spline.positions(w, [t])[0][-1:])
        return np.concatenate(out)

    def retimed(self, time_map) -> "RecordedTask":
        """The task with h's instants moved by a phase step (Sec. VI-B, Eq. 10): a copy whose targets
        (where the recording had the object at each t_k) hold at ``time_map(t_k)``. Where the contact
        is stays; only when it happens moves, as the learned motion's phase does."""
        times = [np.asarray(time_map(t), dtype=float) for t in self.times]
        for old, new in zip(self.times, times):
            if new.shape != old.shape or np.any(np.diff(new) <= 0.0) or (new.size and (
                    new[0] <= 0.0 or new[-1] > self.duration + 1e-9)):
                raise InputError(f"re-timed instants {np.round(new, 3).tolist()} must stay increasing "
                                 f"inside (0, {self.duration}] s")
        task = copy.copy(self)
        task.times = times
        task._targets = [[(float(t),) + x[1:] for t, x in zip(new, xs)] for new, xs in zip(times, self._targets)]
        task._problems = {}
        return task

    @cached_property
    def projection_metric(self):
        """Eq. 18 in ``||L (w - w*)||``, ``L = [A / 100; 0.1 I]`` (A: accelerations): a new theta moves
        the whole motion smoothly instead of bending it at the constrained instants only."""
        import scipy.sparse as sp

        return sp.vstack([self._acceleration.A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()

    def demonstration(self) -> Demonstration:
        """w0: the B-spline fitted to the recording, projected onto h(., theta0) = 0 (Eq. 18)."""
        if not hasattr(self, "_w0"):
            w_fit = self.spline.fit(self.contacts.times, self.contacts.q)
            self._w0, self.demo_report = project_demonstration(self.trajectory_problem(self.theta0), w_fit)
        return Demonstration(self._w0.copy(), self.theta_of(self._w0))

    # -- the rollout -------------------------------------------------------------------------------
    def reference(self, w, rate: float | None = None):
        """Times (N,) and joint references (N, Q) of ``w`` at ``rate`` Hz (default the model's)."""
        rate = 1.0 / self.robot.model.opt.timestep if rate is None else float(rate)
        t = np.arange(int(round(self.duration * rate)) + 1) / rate
        return t, self.spline.positions(w, np.minimum(t, self.duration))

    def run(self, w, on_step=None) -> dict:
        """Simulate ``w`` and log at 100 Hz: ``t`` (N,) s, ``object_q`` (N, j) the object's joints
        (``contacts.object_joints``), ``force`` (N,) N, the contact force between robot and object,
        ``touch`` (N,) bool, ``point`` (N, 3) the robot's contact point (first interval) in the object's
        frame (m), to compare with ``contacts.intervals[0].point``."""
        robot, model, c = self.robot, self.robot.model, self.contacts
        controller = self._controller or servo_controller(robot)
        dt = model.opt.timestep
        every = max(1, int(round(0.01 / dt)))
        obj = robot.id("body", c.object)
        mine = np.flatnonzero(np.isin(model.geom_bodyid, sorted(subtree(model, [obj]))))
        moved = subtree(model, [model.jnt_bodyid[model.dof_jntid[d]] for d in robot.dofs])
        pairs = ContactPairs(model, mine, np.flatnonzero(np.isin(model.geom_bodyid, sorted(moved))))
        qadr = [model.jnt_qposadr[robot.id("joint", j)] for j in c.object_joints]
        frame = self.frames[0]
        log = {"t": [], "object_q": [], "force": [], "touch": [], "point": []}

        def step(k, data):
            if on_step is not None:
                on_step(k, data)
            if k % every:
                return
            R = data.xmat[obj].reshape(3, 3)
            p = np.mean([data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(o)
                         for b, o in zip(frame.ids, frame.offsets)], axis=0)
            log["t"].append(k * dt)
            log["object_q"].append(data.qpos[qadr].copy())
            log["force"].append(float(np.linalg.norm(pairs.force(data))))
            log["touch"].append(pairs(data))
            log["point"].append((p - data.xpos[obj]) @ R)

        track(robot, controller, self.reference(w)[1], self.duration, on_step=step)
        return {k: np.array(v) for k, v in log.items()}

    def rollout(self, w) -> Outcome:
        """``success(log)`` and, on success, ``return_(log)`` of :meth:`run` (a subclass's ``run`` may
        return another log, e.g. a task's own simulation result, for its ``return_`` and ``success``)."""
        log = self.run(w)
        ok = bool(self._success(log))
        touched = {"touched": bool(np.any(log["touch"]))} if isinstance(log, dict) and "touch" in log else {}
        return Outcome(ok, float(self._return(log)) if ok else None, touched)


def pinned_instants(targets: list, theta: np.ndarray, start: float, tolerance: float) -> list[int]:
    """Indices of the ``targets`` (:meth:`RecordedTask._instants`' tuples) h keeps: the first, the
    last, the first at or after ``start``, and more until every target left out lies within
    ``tolerance`` of the straight line in time between the kept ones around it (the contact point
    ``c_k + M_k theta`` in m and the gripper's value, one vector). Greedy (Douglas-Peucker in time:
    the farthest target of a span is kept first), so few, not always the fewest."""
    t = np.array([x[0] for x in targets])
    path = np.array([np.append(base + M @ theta, grip) for _, base, M, _, grip in targets])
    kept = {0, len(t) - 1, int(np.argmax(t >= start - 1e-9))}
    todo = sorted(kept)
    spans = list(zip(todo[:-1], todo[1:]))
    while spans:
        a, b = spans.pop()
        if b - a < 2:
            continue
        s = (t[a + 1:b] - t[a]) / (t[b] - t[a])
        off = np.linalg.norm(path[a + 1:b] - (path[a] + s[:, None] * (path[b] - path[a])), axis=1)
        k = int(np.argmax(off))
        if off[k] > tolerance:
            kept.add(a + 1 + k)
            spans += [(a, a + 1 + k), (a + 1 + k, b)]
    return sorted(kept)


def task_from_recording(scene, joints: Sequence[str] | None, recording, object: str | None, *,
                        return_: Callable, success: Callable, gripper=None, gap: float = 0.1,
                        slide_tolerance: float | None = None, grasp: bool = False, **options) -> RecordedTask:
    """A CORL task from a scene, its moving joints, a recorded demonstration and the object's name.

    Parameters
    ----------
    scene : a :class:`~corl.mujoco.Robot` (its joints are q), or a ``mujoco.MjSpec``, MJCF/URDF path
        or MJCF text with servos on ``joints`` (:func:`~corl.mujoco.add_servos`).
    joints : the joints q moves, in the recording's column order (None with a Robot).
    recording : a :class:`~corl.mujoco.Recording` or a ``.npz`` / ``.csv`` path (:func:`load_recording`).
    object : the body the robot touches (None: the one movable body the recording touches).
    return_, success : ``log -> float`` and ``log -> bool`` on the log of :meth:`RecordedTask.run`.
    gripper : a :class:`~corl.mujoco.Gripper` (its coordinate is q's last column), scene not a Robot.
    gap, slide_tolerance, grasp : see :func:`~corl.mujoco.find_contacts` (``grasp``: the robot holds
        the object in its gripper, whose column then is best the gripper's command: a closed grip's
        position is where the object stopped the fingers, and tracking it does not squeeze).
    **options : for :class:`RecordedTask`: ``name``; ``directions`` (object axes such as ``("-x",)``
        or 3-vectors theta moves the contact along; default the two tangent directions);
        ``theta_bounds`` (default the object's extent along them); ``hold_orientation``,
        ``orientation_weight`` (m/rad); ``approach``, ``spacing`` (s: h's instants); ``tolerance``
        (m: keep only the instants the targets' path needs within this distance, :func:`pinned_instants`;
        default all);
        ``control_points``; ``controller``; ``settings`` (a ``corl.settings.MethodSettings``);
        ``grip_bounds`` (lower, upper): the gripper's value while it holds the object becomes theta's
        last coordinate (e.g. how tight a grasp squeezes), within these bounds.

    Returns
    -------
    RecordedTask : with ``demonstration``, ``cost_residuals``, ``constraint``, ``trajectory_problem``,
        ``theta_of``, ``retimed``, ``projection_metric``, ``rollout``, ``reference``, ``joint_names``,
        ``theta_labels`` derived. Raises :class:`InputError` (one line) when the recording never
        touches the object, touches other movable bodies too, or slides on it.
    """
    robot = _robot(scene, joints, gripper)
    rec = recording if isinstance(recording, Recording) else load_recording(recording)
    contacts = find_contacts(robot, rec, object, gap=gap, slide_tolerance=slide_tolerance, grasp=grasp)
    return RecordedTask(robot, contacts, return_, success, **options)


def _robot(scene, joints, gripper) -> Robot:
    if isinstance(scene, Robot):
        if joints is not None and tuple(joints) != tuple(scene.joints):
            raise InputError(f"joints {list(joints)} differ from the robot's {list(scene.joints)}; pass None")
        return scene
    if not joints:
        raise InputError("name the joints the recording moves (joints=...), in its column order")
    import mujoco

    from corl.mujoco.parse import parse_mjcf
    from corl.mujoco.robot import load_spec

    if not isinstance(scene, mujoco.MjSpec):
        text = str(scene)
        moving = tuple(joints) + (tuple(gripper.joints) if gripper is not None else ())
        scene = parse_mjcf(text, "the scene") if text.lstrip().startswith("<") else load_spec(text, moving=moving)
    return Robot.from_spec(scene, joints, gripper)
