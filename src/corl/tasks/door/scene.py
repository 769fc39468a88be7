"""The MuJoCo scene of the door task (Sec. VIII-B): a PR2 right arm in front of a latched door.

Glossary
--------
q        (8,) task configuration: the 7 right-arm joint angles (rad), then the gripper opening
         width (m, the gap between the fingertip pads).
a        the driven finger angle (rad) of the right gripper; the other finger and both fingertip
         joints follow it through joint equalities, so the gripper has one DoF.
phi      door hinge angle (rad, 0 closed, positive towards the robot).
alpha    handle angle (rad, 0 at rest, positive pressed down).
r        distance along the lever from the handle's pivot (m).

The robot is the PR2 of ``example-robot-data`` (URDF and meshes ship in the wheel, nothing is
downloaded). Its root is ``base_footprint`` without a floating joint, so the base is fixed. Every
joint but the right arm's seven and the right gripper's finger joints is turned to ``fixed`` in the
URDF text before loading. The door hangs on a vertical hinge in front of the right shoulder, opens
towards the robot (``DoorGeometry`` places it; its ``yaw`` turns it about the vertical through the
handle pivot), and is held shut by a latch: a joint equality on the hinge that the simulator
switches off through ``data.eq_active`` once the sprung lever handle is pressed past
``latch_angle``.

Only the fingertips and the palm collide, and only with the door and its handle.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from corl.errors import InputError
from corl.mujoco.equality import add_joint_equality

__all__ = [
    "ARM_JOINTS",
    "DRIVEN_FINGER_JOINT",
    "FOLLOWER_FINGER_JOINTS",
    "DoorGeometry",
    "DoorScene",
    "load_scene",
    "pr2_description_dir",
    "pr2_gripper",
    "width_of_angle",
    "angle_of_width",
]

ARM_JOINTS = (
    "r_shoulder_pan_joint",
    "r_shoulder_lift_joint",
    "r_upper_arm_roll_joint",
    "r_elbow_flex_joint",
    "r_forearm_roll_joint",
    "r_wrist_flex_joint",
    "r_wrist_roll_joint",
)
DRIVEN_FINGER_JOINT = "r_gripper_l_finger_joint"
FOLLOWER_FINGER_JOINTS = (
    "r_gripper_r_finger_joint",
    "r_gripper_l_finger_tip_joint",
    "r_gripper_r_finger_tip_joint",
)
_MOVING_JOINTS = ARM_JOINTS + (DRIVEN_FINGER_JOINT,) + FOLLOWER_FINGER_JOINTS

# PR2 gripper kinematics from the URDF (palm frame, metres): the finger joint sits at
# (0.07691, +-0.01), the fingertip joint at (0.09137, +-0.00495) in the finger frame, and the
# fingertip turns back by the finger angle, so the pads stay parallel.
_FINGER_Y = 0.01
_FINGER_LEN = 0.09137
_TIP_Y = 0.00495
# Inner face of the fingertip pad in the fingertip frame (from the convex hull of l_finger_tip.stl).
PAD_INNER_Y = -0.01585
# Where along the pad (fingertip frame x) the contact point sits: the middle of the flat pad.
PAD_X = 0.004
FINGER_ANGLE_MAX = 0.548

# Arm gains of the position servos (Nm/rad, Nms/rad) and PR2 effort limits (Nm, from the URDF).
# The gains are those of the PR2's default joint-space controllers (pr2_controller_configuration).
ARM_KP = (2400.0, 1200.0, 1000.0, 700.0, 300.0, 300.0, 300.0)
ARM_KV = (18.0, 10.0, 6.0, 4.0, 6.0, 4.0, 4.0)
ARM_EFFORT = (30.0, 30.0, 30.0, 30.0, 30.0, 10.0, 10.0)
ARM_ARMATURE = (0.2, 0.2, 0.1, 0.1, 0.02, 0.02, 0.02)
GRIPPER_KP = 100.0   # Nm/rad on the driven finger angle
GRIPPER_KV = 1.0
GRIPPER_EFFORT = 6.0  # Nm; about 35 N of squeeze at the pads


def width_of_angle(a):
    """Gap between the fingertip pads (m) at finger angle ``a`` (rad); array-friendly."""
    a = np.asarray(a, dtype=float)
    return 2.0 * (_FINGER_Y + _FINGER_LEN * np.sin(a) + _TIP_Y * np.cos(a) + PAD_INNER_Y)


def dwidth_dangle(a):
    """Derivative of :func:`width_of_angle` (m/rad)."""
    a = np.asarray(a, dtype=float)
    return 2.0 * (_FINGER_LEN * np.cos(a) - _TIP_Y * np.sin(a))


_ANGLE_TABLE = np.linspace(0.0, FINGER_ANGLE_MAX, 2001)
_WIDTH_TABLE = width_of_angle(_ANGLE_TABLE)


def angle_of_width(width):
    """Finger angle (rad) that opens the pads ``width`` metres apart (clipped to the joint range)."""
    return np.interp(width, _WIDTH_TABLE, _ANGLE_TABLE)


@dataclass(frozen=True)
class DoorGeometry:
    """Where the door and its handle are, and how they resist (SI units, world = base_footprint).

    The lever points from its pivot towards the hinge (-y); ``handle_height`` is the pivot's height.
    ``yaw`` turns the whole door (slab, hinge, handle) about the vertical axis through the handle
    pivot (rad, counter-clockwise seen from above: positive moves the hinge side away from the
    robot); the pivot stays where ``door_distance``, ``pivot_y`` and ``handle_height`` put it, so
    ``door_distance`` is the door face's distance at the pivot and yaw only turns the door.
    """

    door_distance: float = 0.66      # front face of the door in front of the right shoulder (x)
    pivot_y: float = -0.20           # handle pivot, world y (right shoulder at y = -0.188)
    handle_height: float = 0.85      # handle pivot, world z (right shoulder at z = 0.79)
    lever_length: float = 0.13
    lever_radius: float = 0.011      # a 22 mm bar
    standoff: float = 0.075          # bar axis in front of the door face
    edge_margin: float = 0.06        # pivot to the door's free edge
    door_width: float = 0.85
    door_mass: float = 8.0
    hinge_damping: float = 2.0       # Nms/rad
    hinge_friction: float = 0.5      # Nm
    handle_stiffness: float = 1.0    # Nm/rad (3 Nm/rad is too stiff for the PR2's grip)
    handle_preload: float = 0.3      # rad: the spring's rest angle lies this far above the stop
    handle_range: float = 0.8        # rad, pressed-down stop
    latch_angle: float = 0.4         # rad: the latch releases past this handle angle
    pad_friction: float = 1.2
    yaw: float = 0.0                 # rad, about the vertical through the handle pivot

    def __post_init__(self):
        if not (math.isfinite(self.yaw) and abs(self.yaw) < 0.5 * math.pi):
            raise InputError(f"DoorGeometry.yaw must be a finite angle within +-pi/2 rad, got {self.yaw}")
        for name in ("door_distance", "lever_length", "lever_radius", "standoff", "door_width",
                     "door_mass", "latch_angle", "handle_range"):
            if getattr(self, name) <= 0:
                raise InputError(f"DoorGeometry.{name} must be positive, got {getattr(self, name)}")
        if self.latch_angle >= self.handle_range:
            raise InputError(f"latch_angle {self.latch_angle} must be below handle_range "
                             f"{self.handle_range}, else the door can never unlatch")


@dataclass(frozen=True, eq=False)
class DoorScene:
    """A compiled door scene and the indices a controller, FK or a rollout needs.

    Attributes
    ----------
    model : mujoco.MjModel (shared; do not mutate)
    robot : corl.mujoco.Robot, q = 7 arm joints + the gripper width
    geometry : DoorGeometry
    arm_qpos, arm_dof : (7,) int arrays, qpos and dof addresses of the arm joints
    finger_qpos, finger_dof : int, the driven finger joint
    follower_qpos, follower_dof : (3,) int arrays
    gripper_dofs : (4,) int array, all four finger dofs
    hinge_qpos, hinge_dof, handle_qpos, handle_dof : int
    latch_eq : int, index of the latch equality in ``data.eq_active``
    pad_sites : (2,) int, sites on the two fingertip pads; their midpoint is the contact point
    ft_site : int, the wrist force-torque site
    force_adr, torque_adr : int, sensordata addresses of the wrist force / torque (3 each)
    pivot_world : (3,) the handle pivot with the door closed
    hinge_world : (3,) a point on the hinge axis
    tip_geoms, palm_geoms, handle_geoms, door_geoms : tuples of geom ids
    wrist_body : int, r_wrist_roll_link (the palm is fused into it); its subtree, 1.46 kg, is the hand
    handle_body : int
    """

    model: object
    robot: object
    geometry: DoorGeometry
    arm_qpos: np.ndarray
    arm_dof: np.ndarray
    finger_qpos: int
    finger_dof: int
    follower_qpos: np.ndarray
    follower_dof: np.ndarray
    gripper_dofs: np.ndarray
    hinge_qpos: int
    hinge_dof: int
    handle_qpos: int
    handle_dof: int
    latch_eq: int
    pad_sites: np.ndarray
    ft_site: int
    force_adr: int
    torque_adr: int
    pivot_world: np.ndarray
    hinge_world: np.ndarray
    tip_geoms: tuple
    palm_geoms: tuple
    handle_geoms: tuple
    door_geoms: tuple
    wrist_body: int
    handle_body: int
    joint_lower: np.ndarray = field(repr=False)
    joint_upper: np.ndarray = field(repr=False)

    @property
    def hand_mass(self) -> float:
        """Mass (kg) below the force-torque sensor: the sensor reads its weight at rest."""
        return float(self.model.body_subtreemass[self.wrist_body])

    @property
    def door_rotation(self) -> np.ndarray:
        """(3, 3) orientation of the closed door's frame in the world: the yaw about the vertical."""
        return _rot_z(self.geometry.yaw)

    def door_vector(self, v) -> np.ndarray:
        """A vector (3,) given in the closed door's frame (-x: out of the face towards the robot,
        y: along the face, z: up) in world coordinates (the identity at yaw 0)."""
        v = np.asarray(v, dtype=float)
        return self.door_rotation @ v if self.geometry.yaw != 0.0 else v

    def handle_point(self, r: float, phi: float = 0.0, alpha: float = 0.0) -> np.ndarray:
        """World position (3,) of the bar axis at distance ``r`` from the pivot, door at ``phi``,
        handle at ``alpha``."""
        g = self.geometry
        local = np.array([-g.standoff, -r * math.cos(alpha), -r * math.sin(alpha)])
        return self.door_point(self.pivot_world + self.door_vector(local), phi)

    def along_lever(self, p) -> float:
        """How far (m) the point ``p`` (3,) lies along the closed door's lever at rest, from the
        pivot towards its tip (the bar axis at ``r`` is ``handle_point(r)``: along = r)."""
        d = self.pivot_world - np.asarray(p, dtype=float)
        if self.geometry.yaw == 0.0:
            return float(d[1])
        c, s = math.cos(self.geometry.yaw), math.sin(self.geometry.yaw)
        return float(c * d[1] - s * d[0])

    def door_point(self, p_closed: np.ndarray, phi: float) -> np.ndarray:
        """Where a point fixed to the door at ``p_closed`` (door shut) goes when the door is at ``phi``."""
        c, s = math.cos(phi), math.sin(phi)
        d = np.asarray(p_closed, dtype=float) - self.hinge_world
        return self.hinge_world + np.array([c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _hinge_world(g: DoorGeometry) -> np.ndarray:
    """A point (3,) on the hinge axis (floor height): beside the pivot along the face, turned by the
    yaw about the pivot's vertical."""
    x_face = -0.05 + g.door_distance           # right shoulder pan axis is at x = -0.05
    hinge_y = g.pivot_y + g.edge_margin - g.door_width
    if g.yaw == 0.0:
        return np.array([x_face, hinge_y, 0.0])
    d = _rot_z(g.yaw) @ np.array([0.0, hinge_y - g.pivot_y, 0.0])
    return np.array([x_face + d[0], g.pivot_y + d[1], 0.0])


def pr2_description_dir() -> Path:
    """Folder of the PR2 description inside the installed ``example-robot-data`` wheel."""
    from corl.mujoco import example_robot_dir

    root = example_robot_dir("pr2_description")
    if not (root / "urdf" / "pr2.urdf").is_file():
        raise InputError(f"no PR2 URDF under {root}; reinstall example-robot-data")
    return root


@functools.lru_cache(maxsize=1)
def _pr2_mjcf_text() -> str:
    """The PR2 with all joints but the right arm's and gripper's locked, as MJCF (fixed links fused:
    the palm and everything rigid on it become part of ``r_wrist_roll_link``)."""
    from corl.mujoco import urdf_to_mjcf

    root = pr2_description_dir()
    return urdf_to_mjcf((root / "urdf" / "pr2.urdf").read_text(), moving=_MOVING_JOINTS,
                        package_dirs={"package://example-robot-data/robots/pr2_description/": root})


def pr2_gripper():
    """The PR2 gripper as one coordinate, the width between the pads (m): the driven finger joint
    and its three followers all sit at ``angle_of_width(width)``."""
    from corl.mujoco import Gripper

    return Gripper((DRIVEN_FINGER_JOINT,) + FOLLOWER_FINGER_JOINTS, angle_of=angle_of_width, slope=dwidth_dangle,
                   lower=0.0, upper=float(width_of_angle(FINGER_ANGLE_MAX)))


_HAND_BIT = 2
_PAD_BODIES = ("r_gripper_l_finger_tip_link", "r_gripper_r_finger_tip_link")
WRIST_BODY = "r_wrist_roll_link"


def _build_spec(geometry: DoorGeometry):
    import mujoco

    from corl.mujoco import add_force_sensor, add_servos

    g = geometry
    spec = mujoco.MjSpec.from_string(_pr2_mjcf_text())
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 5.0

    # --- collisions: only fingertips and palm touch, and only the door and its handle
    for body in spec.bodies:
        for geom in body.geoms:
            geom.contype, geom.conaffinity = 0, 0
            if body.name in _PAD_BODIES:
                geom.contype, geom.name = _HAND_BIT, f"{body.name}_pad"
                geom.friction = [g.pad_friction, 0.005, 0.0001]
            elif body.name == WRIST_BODY and geom.meshname == "gripper_palm":
                geom.contype, geom.name = _HAND_BIT, "r_gripper_palm"

    # --- joints: armature, gripper coupling
    for name, arm in zip(ARM_JOINTS, ARM_ARMATURE):
        spec.joint(name).armature = arm
    for name in (DRIVEN_FINGER_JOINT,) + FOLLOWER_FINGER_JOINTS:
        spec.joint(name).armature = 0.002
    for name in FOLLOWER_FINGER_JOINTS:  # q_follower = 0 + 1 * q_driven
        add_joint_equality(spec, name, DRIVEN_FINGER_JOINT, polycoef=(0.0, 1.0), name=f"couple_{name}",
                           solref=[0.004, 1.0])

    # --- sites: fingertip pads and the wrist force-torque frame
    spec.body("r_gripper_l_finger_tip_link").add_site(name="pad_l", pos=[PAD_X, PAD_INNER_Y, 0],
                                                      size=[0.003, 0, 0])
    spec.body("r_gripper_r_finger_tip_link").add_site(name="pad_r", pos=[PAD_X, -PAD_INNER_Y, 0],
                                                      size=[0.003, 0, 0])
    spec.body(WRIST_BODY).add_site(name="wrist_ft", pos=[0, 0, 0], size=[0.005, 0, 0])
    add_force_sensor(spec, "wrist_ft")

    # --- actuators: position servos (PD, with kv integrated implicitly), torque-limited
    add_servos(spec, ARM_JOINTS, ARM_KP, ARM_KV, ARM_EFFORT)
    add_servos(spec, (DRIVEN_FINGER_JOINT,), (GRIPPER_KP,), (GRIPPER_KV,), (GRIPPER_EFFORT,))

    # --- the door: hinge on the robot's right, opening towards the robot
    x_face = -0.05 + g.door_distance           # right shoulder pan axis is at x = -0.05
    hinge_y = g.pivot_y + g.edge_margin - g.door_width
    hinge = _hinge_world(g)
    door = spec.worldbody.add_body(name="door", pos=hinge.tolist())
    if g.yaw != 0.0:  # the door's frame turned about the vertical (its hinge axis stays vertical)
        door.quat = [math.cos(0.5 * g.yaw), 0.0, 0.0, math.sin(0.5 * g.yaw)]
    door.add_joint(name="door_hinge", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1],
                   range=[0.0, 1.6], limited=True, damping=g.hinge_damping,
                   frictionloss=g.hinge_friction)
    door.add_geom(name="door_slab", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.02, g.door_width / 2, 0.98],
                  pos=[0.02, g.door_width / 2, 1.0], mass=g.door_mass, rgba=[0.75, 0.6, 0.4, 1],
                  contype=0, conaffinity=_HAND_BIT)
    pivot_local = [0.0, g.pivot_y - hinge_y, g.handle_height]
    door.add_geom(name="door_rose", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.03, 0.006, 0],
                  pos=[-0.006, pivot_local[1], pivot_local[2]], quat=[0.7071068, 0, 0.7071068, 0],
                  mass=0.05, rgba=[0.7, 0.7, 0.7, 1], contype=0, conaffinity=_HAND_BIT)
    handle = door.add_body(name="handle", pos=pivot_local)
    handle.add_joint(name="handle_hinge", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1, 0, 0],
                     range=[0.0, g.handle_range], limited=True, stiffness=g.handle_stiffness,
                     springref=-g.handle_preload, damping=0.02, armature=0.001)
    handle.add_geom(name="handle_neck", type=mujoco.mjtGeom.mjGEOM_CAPSULE, size=[0.01, 0, 0],
                    fromto=[0, 0, 0, -g.standoff, 0, 0], mass=0.1, rgba=[0.8, 0.8, 0.8, 1],
                    contype=0, conaffinity=_HAND_BIT)
    handle.add_geom(name="handle_bar", type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                    size=[g.lever_radius, 0, 0],
                    fromto=[-g.standoff, 0, 0, -g.standoff, -g.lever_length, 0], mass=0.2,
                    rgba=[0.8, 0.8, 0.8, 1], contype=0, conaffinity=_HAND_BIT,
                    friction=[1.0, 0.005, 0.0001])
    # The latch: hinge angle = 0 while active (Alg.: switched off in the rollout past latch_angle).
    add_joint_equality(spec, "door_hinge", polycoef=(0.0, 0.0), name="latch", solref=[0.004, 1.0],
                       solimp=[0.95, 0.99, 0.001, 0.5, 2])
    spec.worldbody.add_light(pos=[0, 0, 3], dir=[0, 0, -1])
    return spec, x_face, hinge_y


@functools.lru_cache(maxsize=4)
def load_scene(geometry: DoorGeometry | None = None) -> DoorScene:
    """Compile the door scene (cached per process and geometry; about 0.03 s the first time).

    Returns
    -------
    DoorScene
    """
    import mujoco

    from corl.mujoco import Robot

    geometry = geometry or DoorGeometry()
    spec, x_face, hinge_y = _build_spec(geometry)
    model = spec.compile()

    def jid(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

    def gid(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)

    def sid(name):
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)

    arm = np.array([jid(n) for n in ARM_JOINTS])
    followers = np.array([jid(n) for n in FOLLOWER_FINGER_JOINTS])
    finger = jid(DRIVEN_FINGER_JOINT)
    lower = model.jnt_range[arm, 0].copy()
    upper = model.jnt_range[arm, 1].copy()
    unlimited = model.jnt_limited[arm] == 0
    lower[unlimited], upper[unlimited] = -np.inf, np.inf
    force_sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, "wrist_ft_force")
    torque_sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, "wrist_ft_torque")
    ft_site = sid("wrist_ft")
    return DoorScene(
        model=model,
        robot=Robot.from_model(model, ARM_JOINTS, pr2_gripper()),
        geometry=geometry,
        arm_qpos=model.jnt_qposadr[arm].copy(),
        arm_dof=model.jnt_dofadr[arm].copy(),
        finger_qpos=int(model.jnt_qposadr[finger]),
        finger_dof=int(model.jnt_dofadr[finger]),
        follower_qpos=model.jnt_qposadr[followers].copy(),
        follower_dof=model.jnt_dofadr[followers].copy(),
        gripper_dofs=np.concatenate([[model.jnt_dofadr[finger]], model.jnt_dofadr[followers]]),
        hinge_qpos=int(model.jnt_qposadr[jid("door_hinge")]),
        hinge_dof=int(model.jnt_dofadr[jid("door_hinge")]),
        handle_qpos=int(model.jnt_qposadr[jid("handle_hinge")]),
        handle_dof=int(model.jnt_dofadr[jid("handle_hinge")]),
        latch_eq=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, "latch"),
        pad_sites=np.array([sid("pad_l"), sid("pad_r")]),
        ft_site=ft_site,
        force_adr=int(model.sensor_adr[force_sensor]),
        torque_adr=int(model.sensor_adr[torque_sensor]),
        pivot_world=np.array([x_face, geometry.pivot_y, geometry.handle_height]),
        hinge_world=_hinge_world(geometry),
        tip_geoms=(gid("r_gripper_l_finger_tip_link_pad"), gid("r_gripper_r_finger_tip_link_pad")),
        palm_geoms=(gid("r_gripper_palm"),),
        handle_geoms=(gid("handle_bar"), gid("handle_neck")),
        door_geoms=(gid("door_slab"), gid("door_rose")),
        wrist_body=int(model.site_bodyid[ft_site]),
        handle_body=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "handle"),
        joint_lower=lower,
        joint_upper=upper,
    )
