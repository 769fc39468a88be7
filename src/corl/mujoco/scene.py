"""A whole scene in one MJCF (a robot beside a door, a lever, a crate): lock the robot's idle joints,
keep every joint of the objects, and read where the compiled model put things.

Glossary
--------
tree        a body below the world body with everything under it (MuJoCo's kinematic tree)
robot       the trees holding the ``moving`` joints, or the subtrees of ``robot_root``
locked      a joint of the robot that is not ``moving``: deleted, which welds its body to the
            parent in the pose of ``qpos = 0``; free joints are never locked
pose        a body's or site's world position p (3,) and orientation R (3, 3) (columns: its axes)

Scenes that another framework builds (robosuite, a Menagerie ``scene.xml`` saved with
``mj_saveLastXML``) often place their objects in code before compiling, so the XML a user reads
does not show where things are: :func:`body_pose` and :func:`site_pose` read the compiled model.
MuJoCo is imported only when called.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from corl.errors import InputError

__all__ = ["lock_joints", "body_pose", "site_pose"]

_LISTED = 8  # joints named in a message before "and N more"


def _describe(joints) -> str:
    """Names of ``joints`` for a message (an unnamed joint by its body)."""
    names = [j.name or f"<unnamed joint of body {j.parent.name or '?'!r}>" for j in joints]
    more = f" and {len(names) - _LISTED} more" if len(names) > _LISTED else ""
    return ", ".join(names[:_LISTED]) + more


def _lockable(joints, keep: set) -> list:
    """The joints of ``joints`` that are not kept and not free."""
    import mujoco

    free = int(mujoco.mjtJoint.mjJNT_FREE)
    return [j for j in joints if (not j.name or j.name not in keep) and int(j.type) != free]


def _subtree_joints(body) -> list:
    import mujoco

    return list(body.find_all(mujoco.mjtObj.mjOBJ_JOINT))


def _robot_joints(spec, moving: set, robot_root) -> list:
    """Every joint of the robot: the subtrees of ``robot_root``, or the trees holding ``moving``."""
    if robot_root is not None:
        roots = [robot_root] if isinstance(robot_root, str) else list(robot_root)
        joints = []
        for name in roots:
            body = spec.body(name) if isinstance(name, str) and name else None
            if body is None:
                tops = [b.name for b in spec.worldbody.bodies]
                raise InputError(f"robot_root {name!r} is not a body of the MJCF; the bodies below the world are {tops}")
            joints += _subtree_joints(body)
        return list({id(j): j for j in joints}.values())  # nested roots name a joint twice
    if not moving:
        raise InputError("moving is empty, so the robot is unknown: name the robot's joints in moving, "
                         "or give robot_root='<the body the robot hangs from>'")
    trees = [(body, _subtree_joints(body)) for body in spec.worldbody.bodies]
    robot = [(body, joints) for body, joints in trees if any(j.name in moving for j in joints)]
    welded = [j for _, joints in robot for j in _lockable(joints, moving)]
    if len(robot) > 1 and welded:
        raise InputError(f"the moving joints lie in {len(robot)} body trees {[b.name for b, _ in robot]}, so which "
                         f"one is the robot is ambiguous; locking would weld {_describe(welded)}: pass "
                         "robot_root='<the robot's root body>', or list every joint to keep in moving")
    return [j for _, joints in robot for j in joints]


def _delete(spec, element) -> None:
    """Remove ``element`` from ``spec``: ``spec.delete(element)`` from mujoco 3.4 on, ``element.delete()`` before."""
    if hasattr(spec, "delete"):
        spec.delete(element)
    else:  # mujoco 3.3
        element.delete()


def _drop_references(spec, names: set) -> None:
    """Delete the actuators, sensors and joint equalities that need a joint of ``names``, and the
    keyframes (their qpos no longer fits)."""
    import mujoco

    stale = [a for a in spec.actuators
             if int(a.trntype) in (int(mujoco.mjtTrn.mjTRN_JOINT), int(mujoco.mjtTrn.mjTRN_JOINTINPARENT))
             and a.target in names]
    stale += [s for s in spec.sensors if int(s.objtype) == int(mujoco.mjtObj.mjOBJ_JOINT) and s.objname in names]
    stale += [e for e in spec.equalities
              if int(e.type) == int(mujoco.mjtEq.mjEQ_JOINT) and (e.name1 in names or e.name2 in names)]
    for element in stale + list(spec.keys):
        _delete(spec, element)


def lock_joints(spec, *, moving: Sequence[str] | None = None, lock: Sequence[str] = (),
                robot_root: str | Sequence[str] | None = None) -> list[str]:
    """Lock the robot's joints that do not move, in place; keep every joint of the other bodies.

    Parameters
    ----------
    spec : mujoco.MjSpec of the whole scene.
    moving : the robot's joints that stay movable; the robot's other joints are locked. The robot
        is the tree(s) below the world body that hold these joints; when they lie in several trees
        and that would weld a joint not named here, this refuses (pass ``robot_root``).
    lock : joints to lock when ``moving`` is None.
    robot_root : the body (or bodies) the robot hangs from; its subtree is the robot.

    Locked joints are deleted (their bodies weld in the pose of ``qpos = 0``), with the actuators,
    sensors and joint equalities that need them and, when any is locked, the keyframes.

    Returns
    -------
    list of str : what was locked, as named in messages.
    """
    names = [j.name for j in spec.joints if j.name]
    for name in list(moving or ()) + list(lock):
        if name not in names:
            raise InputError(f"joint {name!r} is not in the MJCF; its named joints are {names}")
    if moving is None:
        if robot_root is not None:
            raise InputError("robot_root needs moving=, the robot's joints that stay movable")
        locked = _lockable([j for j in spec.joints if j.name in set(lock)], set())
    else:
        locked = _lockable(_robot_joints(spec, set(moving), robot_root), set(moving))
    described = [_describe([j]) for j in locked]
    if locked:
        _drop_references(spec, {j.name for j in locked if j.name})
        for joint in locked:
            _delete(spec, joint)
    return described


def _pose(model, data, kind: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    import mujoco

    model = getattr(model, "model", model)  # a corl Robot too
    if not isinstance(model, mujoco.MjModel):
        raise InputError(f"{kind}_pose needs a compiled mujoco.MjModel (or a corl Robot), got {type(model).__name__}")
    obj = mujoco.mjtObj.mjOBJ_BODY if kind == "body" else mujoco.mjtObj.mjOBJ_SITE
    k = mujoco.mj_name2id(model, obj, name) if isinstance(name, str) else -1
    if k < 0:
        count = model.nbody if kind == "body" else model.nsite
        known = [mujoco.mj_id2name(model, obj, i) for i in range(count)]
        raise InputError(f"no {kind} named {name!r} in the model; its named {kind}s are {[n for n in known if n][:20]}")
    if data is None:  # the compiled placement: forward kinematics at qpos0
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
    pos, mat = (data.xpos, data.xmat) if kind == "body" else (data.site_xpos, data.site_xmat)
    return pos[k].copy(), mat[k].reshape(3, 3).copy()


def body_pose(model, name: str, data=None) -> tuple[np.ndarray, np.ndarray]:
    """World position (3,) and orientation (3, 3) of body ``name``.

    Parameters
    ----------
    model : compiled ``mujoco.MjModel`` (or a :class:`~corl.mujoco.Robot`).
    name : the body.
    data : a ``mujoco.MjData`` after ``mj_forward`` / ``mj_kinematics`` to read the current pose
        from; None: the compiled placement, at ``qpos0`` (where code put the object before compiling).
    """
    return _pose(model, data, "body", name)


def site_pose(model, name: str, data=None) -> tuple[np.ndarray, np.ndarray]:
    """World position (3,) and orientation (3, 3) of site ``name``; see :func:`body_pose`."""
    return _pose(model, data, "site", name)
