"""A recorded demonstration replayed in the scene: when and where the robot touches an object.

Glossary
--------
recording   times ``t`` (T,) s and joint positions ``q`` (T, Q) as a robot logs them (kinesthetic
            teaching, teleoperation): any rate, any length, uneven steps allowed
replay      the recording interpolated linearly onto the model's timestep ``dt``, the robot's
            joints *prescribed* (position and velocity written every step), everything else
            simulated by ``mj_step``: the object moves as the robot pushes it; a *grasped* object
            (``grasp=True``) follows the pinched point instead (a position log has no grip force)
interval    a stretch of time the robot touches the object (gaps under ``gap`` s are bridged)
offsets     (k, 3) the robot's contact point on each touching body, in that body's frame (m): the
            mean of MuJoCo's contact positions over the interval; the robot's *contact point* is
            their mean (a ``"point"`` frame, :meth:`~corl.mujoco.Kinematics.points`)
point       (3,) the contact point on the object, in the object's frame (m) (Eq. 6's theta0,
            before it is reduced to the surface's tangent directions)
normal      (3,) the contact normal in the object's frame, out of the object towards the robot; of
            a pinch (normals from opposite sides) the squeeze axis
slide       m, how far the robot's contact point moved along the object's surface during an
            interval: more than the tolerance is a sliding contact, the paper's open case (Sec. IX)

Why a prescribed replay and not a kinematic one (``mj_forward`` per sample): the object moves
under the contact (a paddle turns, a door swings), so the contact point must be read in the frame
the object has *then*; a kinematic replay leaves the object where it started and the robot passes
through it. And why not the robot's own servos: the logged positions already are what the servos
achieved; tracking them again would add a second tracking error.

File formats (:func:`load_recording`): ``.npz`` with arrays ``t`` (T,) and ``q`` (T, Q), optional
``joints`` (Q,) names; ``.csv`` with a header ``t,<joint>,...`` and one row per sample.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from corl.errors import InputError
from corl.mujoco.robot import Robot

__all__ = ["Recording", "load_recording", "save_recording", "ContactInterval", "Contacts", "find_contacts"]


@dataclass(frozen=True)
class Recording:
    """A recorded joint trajectory: ``t`` (T,) s, increasing; ``q`` (T, Q) in the task's q order
    (robot joints, then the gripper coordinate); ``joints`` (Q,) column names or ()."""

    t: np.ndarray
    q: np.ndarray
    joints: tuple = ()
    source: str = "recording"

    def __post_init__(self) -> None:
        t, q, where = np.asarray(self.t, dtype=float), np.asarray(self.q, dtype=float), self.source
        if t.ndim != 1 or q.ndim != 2 or q.shape[0] != t.shape[0]:
            raise InputError(f"{where}: t has shape {t.shape} and q {q.shape}; expected t (T,) and q (T, Q)")
        if t.shape[0] < 2:
            raise InputError(f"{where}: {t.shape[0]} sample(s); a recording needs at least two")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
            row = int(np.flatnonzero(~(np.isfinite(t) & np.isfinite(q).all(axis=1)))[0])
            raise InputError(f"{where}: NaN or inf in sample {row}")
        steps = np.diff(t)
        if np.any(steps <= 0):
            k = int(np.flatnonzero(steps <= 0)[0])
            raise InputError(f"{where}: times must increase, but t[{k + 1}] = {t[k + 1]:g} s follows t[{k}] = {t[k]:g} s")
        joints = tuple(str(j) for j in self.joints)
        if joints and len(joints) != q.shape[1]:
            raise InputError(f"{where}: {len(joints)} joint names for {q.shape[1]} columns of q")
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "q", q)
        object.__setattr__(self, "joints", joints)

    @property
    def duration(self) -> float:
        """s from the first sample to the last."""
        return float(self.t[-1] - self.t[0])

    def resampled(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Times from 0 (N,) at ``dt`` over the recording, and ``q`` (N, Q) linearly interpolated."""
        n = int(np.floor(self.duration / dt + 1e-9)) + 1
        t = np.arange(n) * dt
        return t, np.column_stack([np.interp(t + self.t[0], self.t, col) for col in self.q.T])


def load_recording(path) -> Recording:
    """Read a recording from ``.npz`` (arrays ``t`` (T,), ``q`` (T, Q), optional ``joints``) or ``.csv``
    (header ``t,<joint>,...``, one sample per row); one-line :class:`InputError` on a bad file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no recording at {path}")
    suffix = path.suffix.lower()
    if suffix == ".npz":
        try:
            with np.load(path, allow_pickle=False) as f:
                arrays = {k: f[k] for k in f.files}
        except Exception as exc:  # a zip that is no npz, a truncated file, pickled objects
            raise InputError(f"{path}: not a readable .npz ({type(exc).__name__}: {str(exc)[:80]})") from None
        missing = [k for k in ("t", "q") if k not in arrays]
        if missing:
            raise InputError(f"{path}: no array {' or '.join(repr(k) for k in missing)}; a recording .npz holds t (T,) "
                             f"and q (T, Q) (found {sorted(arrays) or 'none'})")
        try:
            t, q = arrays["t"].astype(float), arrays["q"].astype(float)
        except (TypeError, ValueError):
            raise InputError(f"{path}: t and q must be numbers") from None
        joints = tuple(arrays["joints"].tolist()) if "joints" in arrays else ()
        return Recording(t, q, joints, source=str(path))
    if suffix == ".csv":
        return _load_csv(path)
    raise InputError(f"{path}: a recording is a .npz or a .csv file, not {suffix or 'a file without suffix'}")


def _load_csv(path: Path) -> Recording:
    try:
        with path.open(newline="") as f:
            rows = [r for r in csv.reader(f) if r and any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: not a readable CSV ({type(exc).__name__})") from None
    if not rows:
        raise InputError(f"{path}: empty; a recording CSV has a header t,<joint>,... and one row per sample")
    header = [c.strip() for c in rows[0]]
    if header[0] != "t" or len(header) < 2:
        raise InputError(f"{path}: the header must be t,<joint>,... (time first, one column per joint), got "
                         f"{','.join(header)[:80]!r}")
    values = []
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise InputError(f"{path}: row {line} has {len(row)} fields, the header {len(header)}")
        try:
            values.append([float(c) for c in row])
        except ValueError:
            raise InputError(f"{path}: row {line} holds something that is not a number: {','.join(row)[:60]!r}") from None
    data = np.array(values, dtype=float).reshape(-1, len(header))
    return Recording(data[:, 0], data[:, 1:], tuple(header[1:]), source=str(path))


def save_recording(path, t, q, joints: Sequence[str] = ()) -> Path:
    """Write a recording as ``.npz`` (compressed) or ``.csv`` (by ``path``'s suffix); returns the path."""
    rec, path = Recording(t, q, tuple(joints)), Path(path)
    if path.suffix.lower() == ".npz":
        extra = {"joints": np.array(rec.joints)} if rec.joints else {}
        np.savez_compressed(path, t=rec.t, q=rec.q, **extra)
    elif path.suffix.lower() == ".csv":
        names = rec.joints or tuple(f"q{j}" for j in range(rec.q.shape[1]))
        np.savetxt(path, np.column_stack([rec.t, rec.q]), delimiter=",", header=",".join(("t",) + names), comments="",
                   fmt="%.9g")
    else:
        raise InputError(f"{path}: save a recording as .npz or .csv")
    return path


@dataclass(frozen=True)
class ContactInterval:
    """One stretch of contact with the object (times in s from the recording's start).

    Attributes
    ----------
    start, end : s, first and last replay step in contact.
    geoms, bodies : names of the robot's geoms that touched, and of the bodies ``offsets`` refer to.
    offsets : (k, 3) the contact point on each body, in its frame (m).
    point, normal : (3,) the contact point and normal in the object's frame (see the glossary).
    slide : m, the largest tangential move of the robot's contact point on the object.
    """

    start: float
    end: float
    geoms: tuple
    bodies: tuple
    offsets: np.ndarray = field(repr=False)
    point: np.ndarray = field(repr=False)
    normal: np.ndarray = field(repr=False)
    slide: float = 0.0


@dataclass(frozen=True, eq=False)
class Contacts:
    """What a replay found: ``intervals`` with ``object``, and the replay to read poses from.

    Attributes
    ----------
    object : the object's body name; ``object_joints``: names of the joints that move it.
    times : (N,) s from 0 at the model's timestep; ``qpos`` (N, nq) the replayed states.
    q : (N, Q) the recording on the replay's grid (task coordinates).
    size : m, the largest extent of the object's geoms (the scale of its tolerances).
    extent : (8 g, 3) the corners of its geoms' boxes in its frame (for theta's bounds).
    """

    robot: Robot = field(repr=False)
    object: str
    object_joints: tuple
    intervals: tuple
    times: np.ndarray = field(repr=False)
    qpos: np.ndarray = field(repr=False)
    q: np.ndarray = field(repr=False)
    size: float = 0.0
    extent: np.ndarray = field(default=None, repr=False)

    def step(self, t: float) -> int:
        """Index of the replay step nearest ``t`` (s)."""
        return int(np.clip(round(t / float(self.times[1] - self.times[0])), 0, len(self.times) - 1))

    def poses(self, t: float, bodies: Sequence[str] = ()) -> tuple[np.ndarray, np.ndarray, list]:
        """The object's position (3,) and rotation (3, 3) at ``t`` (s), and ``(x, R)`` of each named body."""
        import mujoco

        model = self.robot.model
        data = mujoco.MjData(model)
        data.qpos[:] = self.qpos[self.step(t)]
        mujoco.mj_kinematics(model, data)
        ids = [self.robot.id("body", b) for b in (self.object, *bodies)]
        out = [(data.xpos[k].copy(), data.xmat[k].reshape(3, 3).copy()) for k in ids]
        return out[0][0], out[0][1], out[1:]


def subtree(model, roots) -> set:
    """Body ids of ``roots`` and every body below them."""
    inside = set(int(r) for r in roots)
    for b in range(model.nbody):  # parents come before children in MuJoCo's numbering
        if int(model.body_parentid[b]) in inside and b != 0:
            inside.add(b)
    return inside


def find_contacts(robot: Robot, recording: Recording, object: str | None = None, *, gap: float = 0.1,
                  slide_tolerance: float | None = None, grasp: bool = False, near: float = 0.002) -> Contacts:
    """Replay ``recording`` in ``robot``'s scene and find where the robot touches ``object``.

    Parameters
    ----------
    robot : the scene with the robot (:class:`~corl.mujoco.Robot`); the recording's columns are its q.
    recording : a :class:`Recording` or a path (:func:`load_recording`).
    object : the touched body's name; None: the one movable body the recording touches.
    gap : s, contact breaks shorter than this join one interval.
    slide_tolerance : m, the largest slide of a contact (default 5 % of the object's size).
    near : m, a longer break in contact during which the robot's touching geoms stay this close to
        the object does not end the interval: a pushed object that the contact solver lets bounce
        a millimetre ahead of the fingers is still being pushed (how far and how long it bounces
        differs between MuJoCo versions).
    grasp : the robot grasps ``object`` (it must be named): from the first step its bodies touch it
        from opposite sides (a pinch) until they all let go, the object's joints follow the grasped
        point (least squares) instead of being simulated. A joint-position log holds no grip force,
        and a prescribed replay passes none on: a grasped handle would stay put and the fingers slide
        off it.

    Raises
    ------
    InputError
        One line: the recording never touches the object, touches other movable bodies too, or its
        contact point slides along the object (naming the interval).
    """
    import mujoco

    rec = recording if isinstance(recording, Recording) else load_recording(recording)
    model, where = robot.model, rec.source
    if rec.q.shape[1] != robot.dim:
        raise InputError(f"{where}: {rec.q.shape[1]} joint columns, the robot's q has {robot.dim} "
                         f"({', '.join(robot.joints)}{' + gripper' if robot.gripper else ''})")
    if rec.joints and rec.joints[:robot.num_joints] != tuple(robot.joints):
        raise InputError(f"{where}: columns {list(rec.joints)} are not the robot's joints {list(robot.joints)} in order")
    if grasp and object is None:
        raise InputError("grasp=True needs the grasped object's name")
    if not (np.isfinite(near) and 0 <= near < 0.05):
        raise InputError(f"near={near!r}: give the distance in m, in [0, 0.05)")
    dt = float(model.opt.timestep)
    times, q = rec.resampled(dt)
    holder = _Holder(model, robot.id("body", object)) if grasp else None
    moved = subtree(model, [model.jnt_bodyid[model.dof_jntid[d]] for d in robot.dofs])
    body_of = model.geom_bodyid
    data = mujoco.MjData(model)
    J, dofs = robot.num_joints, robot.dofs
    angle = robot.gripper.angle(q[:, J]) if robot.gripper else np.zeros(len(q))
    dq = np.gradient(np.column_stack([q[:, :J]] + [angle[:, None] * r for r in robot.ratios]), dt, axis=0)
    qpos, records = np.empty((len(times), model.nq)), []  # records: (step, robot geom, other geom, pos, normal)
    for k in range(len(times)):
        robot.write(data, q[k])
        data.qvel[dofs] = dq[k]
        if holder is not None:
            holder.follow(data, dt)
        mujoco.mj_forward(model, data)
        qpos[k] = data.qpos
        step = []
        for c in data.contact[: data.ncon]:
            g1, g2 = int(c.geom1), int(c.geom2)
            a, b = body_of[g1] in moved, body_of[g2] in moved
            if a != b:  # robot against something else; the normal points from geom1 to geom2
                n = np.array(c.frame[:3]) * (1.0 if b else -1.0)  # out of the other geom, towards the robot
                step.append((k, g2 if b else g1, g1 if b else g2, np.array(c.pos), n))
        records += step
        if holder is not None:
            holder.update(data, step)
        mujoco.mj_step(model, data)
    name = lambda kind, i: mujoco.mj_id2name(model, kind, int(i)) or f"#{int(i)}"  # noqa: E731
    touched = {}  # movable body -> steps
    for k, _, other, _, _ in records:
        body = int(body_of[other])
        if model.body_weldid[body] != 0:  # bodies welded to the world (a table) are no candidates
            touched.setdefault(body, []).append(k)
    span = lambda steps: f"{times[min(steps)]:.2f}-{times[max(steps)]:.2f} s"  # noqa: E731
    found = ", ".join(f"'{name(mujoco.mjtObj.mjOBJ_BODY, b)}' ({span(s)})" for b, s in touched.items())
    if object is None:
        if len(touched) != 1:
            raise InputError(f"{where}: the recording touches {found or 'nothing'}; name the object to learn with")
        object = name(mujoco.mjtObj.mjOBJ_BODY, next(iter(touched)))
    obj = robot.id("body", object)
    mine = subtree(model, [obj])
    if not any(b in mine for b in touched):
        raise InputError(f"{where}: the recording never touches '{object}' ({rec.duration:.2f} s replayed at "
                         f"{1 / dt:.0f} Hz); it touches {found or 'nothing'}")
    others = [b for b in touched if b not in mine]
    if others:
        raise InputError(f"{where}: the recording touches several candidate objects: {found}; h holds one "
                         f"object's contact point, record the motion with '{object}' alone")
    return _analyse(robot, rec, object, times, q, qpos, [r for r in records if body_of[r[2]] in mine], gap,
                    slide_tolerance, near)


class _Holder:
    """The grasped object of a replay: its joints follow the robot's grasp point while held."""

    def __init__(self, model, obj: int) -> None:
        self.model, self.obj = model, obj
        self.mine = subtree(model, [obj])
        chain = _chain(model, obj)
        joints = [j for j in range(model.njnt) if model.jnt_bodyid[j] in chain and model.jnt_type[j] in (2, 3)]
        self.qadr = np.array([model.jnt_qposadr[j] for j in joints], dtype=int)
        self.dadr = np.array([model.jnt_dofadr[j] for j in joints], dtype=int)
        self.held = None  # (robot bodies, their offsets (k, 3), the point in the object's frame (3,))

    def update(self, data, step) -> None:
        """Start holding at a pinch (normals on the object more than 120 deg apart), stop when no
        robot body touches it any more."""
        mine = [r for r in step if self.model.geom_bodyid[r[2]] in self.mine]
        if self.held is not None:
            if not mine:
                self.held = None
            return
        normals = np.array([r[4] for r in mine]).reshape(-1, 3)
        if len(self.qadr) == 0 or len(mine) < 2 or not np.min(normals @ normals.T) < -0.5:
            return
        bodies = sorted({int(self.model.geom_bodyid[r[1]]) for r in mine})
        point = np.mean([r[3] for r in mine], axis=0)
        offsets = np.array([(point - data.xpos[b]) @ data.xmat[b].reshape(3, 3) for b in bodies])
        R = data.xmat[self.obj].reshape(3, 3)
        self.held = (bodies, offsets, (point - data.xpos[self.obj]) @ R)

    def follow(self, data, dt: float, iterations: int = 8) -> None:
        """Move the object's joints (qpos, qvel) so that its held point lies on the robot's."""
        import mujoco

        if self.held is None:
            return
        model, (bodies, offsets, local) = self.model, self.held
        before = data.qpos[self.qadr].copy()
        jac = np.zeros((3, model.nv))
        for _ in range(iterations):
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)
            target = np.mean([data.xpos[b] + data.xmat[b].reshape(3, 3) @ o for b, o in zip(bodies, offsets)], axis=0)
            here = data.xpos[self.obj] + data.xmat[self.obj].reshape(3, 3) @ local
            error = target - here
            if np.linalg.norm(error) < 1e-7:
                break
            mujoco.mj_jac(model, data, jac, None, here, self.obj)
            A = jac[:, self.dadr]
            data.qpos[self.qadr] += np.linalg.lstsq(A, error, rcond=None)[0]
        data.qvel[self.dadr] = (data.qpos[self.qadr] - before) / dt


def _close(model, data, qpos, robot_geoms, object_geoms, first: int, last: int, near: float) -> bool:
    """Whether some robot geom stays within ``near`` of the object at every step first..last."""
    import mujoco

    for k in range(first, last + 1):
        data.qpos[:] = qpos[k]
        mujoco.mj_kinematics(model, data)
        if not any(mujoco.mj_geomDistance(model, data, int(a), int(b), near, None) < near  # distmax when farther
                   for a in robot_geoms for b in object_geoms):
            return False
    return True


def _analyse(robot, rec, object, times, q, qpos, records, gap, slide_tolerance, near) -> Contacts:
    """Intervals, points and slides from the contact records of a replay."""
    import mujoco

    model = robot.model
    data, obj = mujoco.MjData(model), robot.id("body", object)
    data.qpos[:] = qpos[0]
    mujoco.mj_kinematics(model, data)
    mine = sorted(subtree(model, [obj]))
    x0, r0 = data.xpos[obj].copy(), data.xmat[obj].reshape(3, 3).copy()
    corners = []
    for g in np.flatnonzero(np.isin(model.geom_bodyid, mine)):
        centre, half = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        world = data.geom_xpos[g] + (centre + signs * half) @ data.geom_xmat[g].reshape(3, 3).T
        corners.append((world - x0) @ r0)
    extent = np.vstack(corners) if corners else np.zeros((1, 3))
    extent = extent[np.all(np.isfinite(extent), axis=1)]
    size = float(np.max(np.ptp(extent, axis=0))) if len(extent) else 0.0
    tol = 0.05 * size if slide_tolerance is None else float(slide_tolerance)
    steps = np.array(sorted({r[0] for r in records}))
    dt = float(times[1] - times[0])
    object_geoms = np.flatnonzero(np.isin(model.geom_bodyid, mine))
    breaks = [i for i in np.flatnonzero(np.diff(steps) * dt > gap)  # bridged while the touching geoms stay near
              if not _close(model, data, qpos, sorted({r[1] for r in records if r[0] in (steps[i], steps[i + 1])}),
                            object_geoms, int(steps[i]) + 1, int(steps[i + 1]) - 1, near)]
    runs = np.split(steps, np.array(breaks, dtype=int) + 1)
    joints = []
    for b in _chain(model, obj):
        joints += [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"#{j}"
                   for j in np.flatnonzero(model.jnt_bodyid == b)]
    intervals = []
    for run in runs:
        inside = [r for r in records if run[0] <= r[0] <= run[-1]]
        per_body: dict = {}
        normals = []
        for k, g, _, pos, n in inside:
            data.qpos[:] = qpos[k]
            mujoco.mj_kinematics(model, data)
            body = int(model.geom_bodyid[g])
            per_body.setdefault(body, []).append(((pos - data.xpos[body]) @ data.xmat[body].reshape(3, 3), g))
            normals.append(n @ data.xmat[obj].reshape(3, 3))
        bodies = sorted(per_body)
        offsets = np.array([np.mean([o for o, _ in per_body[b]], axis=0) for b in bodies])
        geoms = sorted({mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) or f"#{g}"
                        for b in bodies for _, g in per_body[b]})
        normal = np.mean(normals, axis=0)
        if np.linalg.norm(normal) < 0.5:  # a pinch from opposite sides: the squeeze axis
            normal = np.linalg.eigh(np.asarray(normals).T @ np.asarray(normals))[1][:, -1]
        normal /= max(np.linalg.norm(normal), 1e-12)
        track = []  # the robot's contact point in the object's frame, every step of the interval
        for k in range(int(run[0]), int(run[-1]) + 1):
            data.qpos[:] = qpos[k]
            mujoco.mj_kinematics(model, data)
            p = np.mean([data.xpos[b] + data.xmat[b].reshape(3, 3) @ o for b, o in zip(bodies, offsets)], axis=0)
            track.append((p - data.xpos[obj]) @ data.xmat[obj].reshape(3, 3))
        track = np.array(track)
        point = track.mean(axis=0)
        along = (track - point) - np.outer((track - point) @ normal, normal)  # tangential part
        few = along[:: max(1, len(along) // 200)]  # the largest distance between two of its positions
        slide = float(np.max(np.linalg.norm(few[:, None] - few[None], axis=2)))
        start, end = float(times[run[0]]), float(times[run[-1]])
        if slide > tol:
            raise InputError(f"{rec.source}: the contact with '{object}' slid {slide * 1e3:.1f} mm along its surface "
                             f"during {start:.2f}-{end:.2f} s (tolerance {tol * 1e3:.1f} mm): sliding contacts are the "
                             "paper's open case (h holds a contact point fixed on the object); record a motion that "
                             "holds it still, or raise slide_tolerance")
        names = tuple(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) for b in bodies)
        intervals.append(ContactInterval(start, end, tuple(geoms), names, offsets, point, normal, slide))
    return Contacts(robot, object, tuple(joints), tuple(intervals), times, qpos, q, size, extent)


def _chain(model, body: int) -> list:
    """Body ids from the world down to ``body`` (the bodies whose joints move it)."""
    chain = []
    while body > 0:
        chain.append(body)
        body = int(model.body_parentid[body])
    return chain[::-1]
