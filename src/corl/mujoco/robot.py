"""Load a robot for CORL from an MJCF or URDF file: the joints it moves, the ones it locks, and a
gripper driven as one coordinate.

Glossary
--------
q        (Q,) task configuration: the positions of the robot's ``joints`` (rad or m), then, when
         the robot has a gripper, the gripper coordinate ``c`` (Q = len(joints) + 1)
c        gripper coordinate, e.g. the opening width (m)
a        the gripper's driven angle: ``a = angle_of(c)``; gripper joint i sits at ``ratios[i] a``
slope    ``dc / da`` at ``a``: turns the joints' Jacobian columns into the column of ``c``

A URDF is compiled once on its own and saved back as MJCF, so that MuJoCo fuses the links that the
locked joints leave rigid (MuJoCo 3.3 stops fusing static bodies once a spec gains an actuator,
sensor, equality or light); the returned :class:`mujoco.MjSpec` can then take a scene, servos and
sensors. Everything here imports MuJoCo only when called.
"""

from __future__ import annotations

import itertools
import os
import re
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from corl.errors import InputError, MissingExtraError
from corl.mujoco.parse import compile_spec, one_line, parse_mjcf
from corl.mujoco.scene import lock_joints

__all__ = ["Gripper", "Robot", "load_spec", "urdf_to_mjcf", "example_robot_dir"]

_COMPILER = '<mujoco><compiler strippath="false" fusestatic="true" balanceinertia="true"/></mujoco>'


def _mujoco():
    try:
        import mujoco
    except ImportError:  # pragma: no cover - mujoco is a dependency of corl
        raise MissingExtraError("the MuJoCo kit needs the 'mujoco' package (pip install mujoco)") from None
    return mujoco


@dataclass(frozen=True)
class Gripper:
    """A gripper as one coordinate ``c``: its joints follow one driven angle ``a = angle_of(c)``.

    Parameters
    ----------
    joints : names of the gripper joints; the first is the driven one (its servo sets ``a``).
    ratios : (k,) joint i sits at ``ratios[i] * a``; default all 1 (joint equalities or mimics).
    angle_of : ``c -> a``, array-friendly; default the identity.
    slope : ``a -> dc/da``, array-friendly; default 1.
    lower, upper : range of ``c`` (IK keeps ``c`` as given; limits are for the user).

    Examples
    --------
    A Panda hand whose two slide fingers open ``c`` metres in total::

        Gripper(("panda_finger_joint1", "panda_finger_joint2"), angle_of=lambda c: 0.5 * c,
                slope=lambda a: 2.0 + 0.0 * a)
    """

    joints: tuple
    ratios: tuple | None = None
    angle_of: Callable | None = None
    slope: Callable | None = None
    lower: float = -np.inf
    upper: float = np.inf

    def __post_init__(self) -> None:
        joints = tuple(self.joints)
        if not joints or not all(isinstance(j, str) and j for j in joints):
            raise InputError(f"Gripper.joints must be a non-empty sequence of joint names, got {self.joints!r}")
        object.__setattr__(self, "joints", joints)
        ratios = (1.0,) * len(joints) if self.ratios is None else tuple(float(r) for r in self.ratios)
        if len(ratios) != len(joints) or not all(np.isfinite(ratios)) or ratios[0] == 0.0:
            raise InputError(f"Gripper.ratios must give one finite factor per joint ({len(joints)}), "
                             f"the first non-zero; got {self.ratios!r}")
        object.__setattr__(self, "ratios", ratios)
        for name in ("angle_of", "slope"):
            if getattr(self, name) is not None and not callable(getattr(self, name)):
                raise InputError(f"Gripper.{name} must be callable or None, got {getattr(self, name)!r}")

    def angle(self, c):
        """Driven angle ``a`` of coordinate ``c`` (scalar or array)."""
        return c if self.angle_of is None else self.angle_of(c)

    def dc_da(self, a):
        """``dc/da`` at driven angle ``a``."""
        return 1.0 if self.slope is None else self.slope(a)


def _read(source) -> tuple[str, Path | None]:
    """XML text and the folder it came from (None for text)."""
    if isinstance(source, str) and source.lstrip().startswith("<"):
        return source, None
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"load_spec needs a file path or XML text, got {type(source).__name__}")
    path = Path(source)
    if not path.is_file():
        raise InputError(f"robot file {str(path)!r} does not exist; give the path of an MJCF (.xml) or URDF (.urdf) file")
    return path.read_text(), path.parent.resolve()


def urdf_to_mjcf(urdf_text: str, *, moving: Sequence[str] | None = None, lock: Sequence[str] = (),
                 package_dirs: Mapping[str, str | os.PathLike] | None = None,
                 base_dir: str | os.PathLike | None = None) -> str:
    """Turn URDF text into MJCF text with locked joints fused into their parents.

    Parameters
    ----------
    urdf_text : the URDF.
    moving : joints that stay movable; every other joint becomes ``fixed``. None: all but ``lock``.
    lock : joints that become ``fixed`` (used when ``moving`` is None).
    package_dirs : ``{"package://prefix/": folder}`` replacements for mesh paths; a relative mesh
        path is taken relative to ``base_dir``.
    base_dir : folder of the URDF file.

    Notes
    -----
    Visual, gazebo and transmission blocks and mimic tags are dropped (MuJoCo reads no .dae and
    couples joints with equalities instead); collisions are named ``collision0, 1, ...``.

    Returns
    -------
    str : MJCF text (for :meth:`mujoco.MjSpec.from_string`).
    """
    mujoco = _mujoco()
    text = urdf_text
    for prefix, folder in (package_dirs or {}).items():
        text = text.replace(prefix, f"{Path(folder)}/")
    if base_dir is not None:
        text = re.sub(r'filename="(?!/|package://)([^"]+)"', lambda m: f'filename="{Path(base_dir) / m.group(1)}"', text)
    unresolved = re.search(r'filename="(package://[^"]+)"', text)
    if unresolved:
        raise InputError(f"mesh {unresolved.group(1)!r} has no folder; pass package_dirs="
                         "{'package://<prefix>/': '<folder>'} to load_spec")
    names = set(re.findall(r'<joint name="([^"]*)"', text))
    for name in list(moving or ()) + list(lock):
        if name not in names:
            raise InputError(f"joint {name!r} is not in the URDF; its joints are {sorted(names)}")
    keep = set(moving) if moving is not None else names - set(lock)

    def fix(match):
        return match.group(0) if match.group(1) in keep else f'<joint name="{match.group(1)}" type="fixed"'

    text = re.sub(r'<joint name="([^"]*)" type="([^"]*)"', fix, text)
    for block in ("visual", "gazebo", "transmission"):
        text = re.sub(rf"<{block}\b.*?</{block}>", "", text, flags=re.S)
    text = re.sub(r"<mimic[^>]*/>", "", text)
    counter = itertools.count()
    text = re.sub(r"<collision>", lambda _: f'<collision name="collision{next(counter)}">', text)
    text = re.sub(r"(<robot [^>]*>)", r"\1" + _COMPILER, text, count=1)
    try:
        model = mujoco.MjModel.from_xml_string(text)
    except ValueError as exc:
        message = one_line(exc)
        hint = ("check the mesh paths: pass package_dirs= for package:// paths, or the URDF's path rather than "
                "its text for relative ones") if "opening file" in message.lower() else "fix the URDF"
        raise InputError(f"cannot read the URDF: {message}; {hint}") from None
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "robot.xml")
        mujoco.mj_saveLastXML(path, model)
        with open(path) as f:
            return f.read()


def load_spec(source, *, moving: Sequence[str] | None = None, lock: Sequence[str] = (),
              robot_root: str | Sequence[str] | None = None,
              package_dirs: Mapping[str, str | os.PathLike] | None = None):
    """Load an MJCF or URDF robot, or a whole MJCF scene, as an editable :class:`mujoco.MjSpec`, the
    robot's idle joints locked.

    Parameters
    ----------
    source : path of an ``.xml`` (MJCF) or ``.urdf`` file, or the XML text itself.
    moving : the robot's joints that stay movable; the robot's other joints are locked. None: all
        but ``lock``.
    lock : joints to lock (when ``moving`` is None).
    robot_root : MJCF only: the body (or bodies) the robot hangs from. Default: the trees below the
        world body that hold the ``moving`` joints (see :func:`corl.mujoco.scene.lock_joints`).
    package_dirs : URDF only, see :func:`urdf_to_mjcf`.

    Notes
    -----
    A locked joint holds its zero position: in a URDF it becomes ``fixed``; in an MJCF it is
    deleted, which welds its body to the parent in the pose of ``qpos = 0`` (with the actuators,
    sensors and joint equalities that need it, and the keyframes). Joints of the other bodies of an
    MJCF scene (a door's hinge, a latch) and free joints are never locked. An MJCF is compiled once
    here, so a missing mesh or a repeated name is refused now.

    Returns
    -------
    mujoco.MjSpec : add the scene, servos (:func:`corl.mujoco.add_servos`) and sensors, then
        compile it into a :class:`Robot` with :meth:`Robot.from_spec`.

    Raises
    ------
    InputError : a missing or malformed file, an unknown joint, or a robot that the ``moving``
        joints leave ambiguous (the message lists what would be welded).
    """
    text, folder = _read(source)
    if re.search(r"<robot\b", text[:2000]):
        if robot_root is not None:
            raise InputError("robot_root is for MJCF scenes; a URDF holds one robot: leave it out")
        mjcf = urdf_to_mjcf(text, moving=moving, lock=lock, package_dirs=package_dirs, base_dir=folder)
        return parse_mjcf(mjcf, "MJCF made from the URDF")
    spec = parse_mjcf(text if folder is None else Path(source))
    lock_joints(spec, moving=moving, lock=lock, robot_root=robot_root)
    compile_spec(spec, "MJCF with its joints locked")
    return spec


def example_robot_dir(name: str) -> Path:
    """Folder of robot ``name`` (a plain folder name, e.g. ``"panda_description"``) in the installed
    ``example-robot-data``."""
    from importlib import metadata

    if not (isinstance(name, str) and re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name)):
        raise InputError(f"robot name {name!r} is not a plain folder name of example-robot-data "
                         "(e.g. 'panda_description'); give the name of one folder, without slashes")
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise InputError("this robot needs the 'example-robot-data' package (pip install example-robot-data==6.0.0)") from None
    root = Path(dist.locate_file(f"cmeel.prefix/share/example-robot-data/robots/{name}"))
    if not root.is_dir():
        raise InputError(f"no robot {name!r} in example-robot-data (folder {root} missing)")
    return root


@dataclass(frozen=True, eq=False)
class Robot:
    """A compiled model and where the task configuration ``q`` lives in it.

    Attributes
    ----------
    model : mujoco.MjModel (shared; do not mutate)
    joints : names of the joints q moves, in order; the gripper coordinate comes last
    gripper : Gripper or None
    qpos, dof : (J,) int, qpos and dof addresses of ``joints``
    gripper_qpos, gripper_dof : (k,) int (empty without a gripper)
    ratios : (k,) float, :attr:`Gripper.ratios`
    lower, upper : (Q,) limits of q (inf where a joint is unlimited)
    """

    model: object
    joints: tuple
    gripper: Gripper | None
    qpos: np.ndarray
    dof: np.ndarray
    gripper_qpos: np.ndarray
    gripper_dof: np.ndarray
    ratios: np.ndarray
    lower: np.ndarray = field(repr=False)
    upper: np.ndarray = field(repr=False)

    @classmethod
    def from_model(cls, model, joints: Sequence[str], gripper: Gripper | None = None) -> "Robot":
        """Index a compiled ``mujoco.MjModel``: ``joints`` (names, in q's order) and the ``gripper``."""
        mujoco = _mujoco()

        def jid(name):
            k = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
            if k < 0:
                raise InputError(f"joint {name!r} is not in the model (was it locked?)")
            # int(): under mujoco >= 3.1x, ``np.int32 in (enum, ...)`` is False although ``==`` holds
            if int(model.jnt_type[k]) not in (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE)):
                raise InputError(f"joint {name!r} is not a hinge or slide; q holds one value per joint")
            return k

        joints = tuple(joints)
        if not joints:
            raise InputError("a robot needs at least one joint in q")
        ids = np.array([jid(n) for n in joints], dtype=int)
        gids = np.array([jid(n) for n in gripper.joints], dtype=int) if gripper else np.zeros(0, dtype=int)
        lower = model.jnt_range[ids, 0].copy()
        upper = model.jnt_range[ids, 1].copy()
        unlimited = model.jnt_limited[ids] == 0
        lower[unlimited], upper[unlimited] = -np.inf, np.inf
        if gripper is not None:
            lower, upper = np.append(lower, gripper.lower), np.append(upper, gripper.upper)
        return cls(model=model, joints=joints, gripper=gripper, qpos=model.jnt_qposadr[ids].copy(),
                   dof=model.jnt_dofadr[ids].copy(), gripper_qpos=model.jnt_qposadr[gids].copy(),
                   gripper_dof=model.jnt_dofadr[gids].copy(),
                   ratios=np.array(gripper.ratios if gripper else (), dtype=float), lower=lower, upper=upper)

    @classmethod
    def from_spec(cls, spec, joints: Sequence[str], gripper: Gripper | None = None) -> "Robot":
        """Compile ``spec`` (a :class:`mujoco.MjSpec`) and index it, see :meth:`from_model`."""
        return cls.from_model(compile_spec(spec), joints, gripper)

    @property
    def num_joints(self) -> int:
        """J, the robot joints in q (without the gripper coordinate)."""
        return len(self.joints)

    @property
    def dim(self) -> int:
        """Q, the length of q."""
        return len(self.joints) + (self.gripper is not None)

    @property
    def dofs(self) -> np.ndarray:
        """(J + k,) dof addresses of every joint q drives (arm, then gripper)."""
        return np.concatenate([self.dof, self.gripper_dof])

    def check_q(self, q) -> np.ndarray:
        """``q`` as a float vector of shape (Q,), or an InputError naming the expected layout."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.dim,):
            grip = " + gripper coordinate" if self.gripper else ""
            raise InputError(f"q has shape {q.shape}, expected ({self.dim},) = {self.num_joints} joints{grip}")
        if not np.all(np.isfinite(q)):
            raise InputError(f"q contains NaN or inf at {np.flatnonzero(~np.isfinite(q)).tolist()}: "
                             "give finite joint positions")
        return q

    def write(self, data, q: np.ndarray) -> None:
        """Write ``q`` (Q,) into ``data.qpos`` (no kinematics update)."""
        J = self.num_joints
        data.qpos[self.qpos] = q[:J]
        if self.gripper is not None:
            angle = self.gripper.angle(q[J])
            data.qpos[self.gripper_qpos] = self.ratios * angle

    def read(self, data) -> np.ndarray:
        """The robot joints of ``data.qpos`` (J,) (the gripper coordinate is not inverted)."""
        return data.qpos[self.qpos].copy()

    def id(self, kind: str, name: str) -> int:
        """MuJoCo id of a ``"site"``, ``"body"``, ``"geom"``, ``"sensor"`` or ``"joint"`` by name
        (e.g. an object's hinge: its angle is ``data.qpos[model.jnt_qposadr[id]]``)."""
        mujoco = _mujoco()
        obj = {"site": mujoco.mjtObj.mjOBJ_SITE, "body": mujoco.mjtObj.mjOBJ_BODY,
               "geom": mujoco.mjtObj.mjOBJ_GEOM, "sensor": mujoco.mjtObj.mjOBJ_SENSOR,
               "joint": mujoco.mjtObj.mjOBJ_JOINT}.get(kind)
        if obj is None:
            raise InputError(f"kind must be site, body, geom, sensor or joint, got {kind!r}")
        k = mujoco.mj_name2id(self.model, obj, name)
        if k < 0:
            raise InputError(f"no {kind} named {name!r} in the model")
        return int(k)
