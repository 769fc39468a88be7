"""A MuJoCo kit for any robot: from an MJCF or URDF to the pieces of a CORL task.

==============================  ================================================================
step                            functions
==============================  ================================================================
load, lock joints, gripper      :func:`load_spec`, :class:`Gripper`, :class:`Robot`,
                                :func:`example_robot_dir`, :func:`parse_mjcf` (MJCF text or file
                                to an ``MjSpec``, nothing locked)
a scene from another framework  :func:`load_spec` (``robot_root``), :func:`body_pose`,
                                :func:`site_pose`
forward kinematics (Eq. 6)      :class:`Kinematics` (``site``, ``body``, ``position_jacobian``,
                                ``rotation_jacobian``), :func:`rotation_error`
Eq. 6 features                  :func:`position_feature`, :func:`orientation_feature`,
                                :func:`coordinate_feature`, :func:`stack`
demonstration                   :class:`Target`, :func:`solve_ik`, :func:`solve_waypoints`,
                                :func:`fit_demonstration`, :func:`project_demonstration`
rollout                         :func:`add_servos`, :class:`PDController`, :func:`track`,
                                :func:`add_joint_equality` (coupled fingers, a latch)
forces                          :func:`add_force_sensor`, :class:`ForceSensor`,
                                :func:`contact_force`, :func:`touching`, :class:`ContactPairs`
                                (the same two, with lookup tables built once: for every step)
a task from a recording         :func:`task_from_recording` (scene, joints, recording, object,
                                ``return_``, ``success``: h, theta, theta_of, w0 derived),
                                :class:`RecordedTask`, :func:`load_recording`, :func:`save_recording`,
                                :class:`Recording`, :func:`find_contacts` (replay: contact intervals,
                                :class:`Contacts`, :class:`ContactInterval`), :func:`servo_controller`
video                           :class:`Camera`, :class:`FrameRecorder`, :func:`caption`,
                                :func:`write_side_by_side`, :func:`rendering_available`,
                                :func:`make_renderer`
==============================  ================================================================

Every module imports MuJoCo only inside the functions that need it, so ``import corl.mujoco`` is
as light as numpy. ``examples/panda_switch.py`` builds a whole task with it; the PR2 door
(:mod:`corl.tasks.door`) uses it too.
"""

from corl.mujoco.control import PDController, add_servo, add_servos, dense_reference, track
from corl.mujoco.equality import add_joint_equality
from corl.mujoco.demo import ProjectionReport, fit_demonstration, piecewise_linear, project_demonstration
from corl.mujoco.features import coordinate_feature, orientation_feature, position_feature, stack
from corl.mujoco.forces import (ContactPairs, ForceSensor, add_force_sensor, contact_force, remove_static_load,
                               touching)
from corl.mujoco.ik import Target, solve_ik, solve_waypoints
from corl.mujoco.kinematics import Frame, Kinematics, rotation_error, rotation_error_jacobian, skew
from corl.mujoco.parse import parse_mjcf
from corl.mujoco.recorded import RecordedTask, servo_controller, task_from_recording
from corl.mujoco.recording import (ContactInterval, Contacts, Recording, find_contacts, load_recording,
                                   save_recording)
from corl.mujoco.robot import Gripper, Robot, example_robot_dir, load_spec, urdf_to_mjcf
from corl.mujoco.scene import body_pose, site_pose
from corl.mujoco.video import (Camera, FrameRecorder, caption, make_renderer, rendering_available,
                               write_side_by_side)

__all__ = [
    "Gripper", "Robot", "load_spec", "parse_mjcf", "urdf_to_mjcf", "example_robot_dir", "body_pose", "site_pose",
    "Frame", "Kinematics", "rotation_error", "rotation_error_jacobian", "skew",
    "position_feature", "orientation_feature", "coordinate_feature", "stack",
    "Target", "solve_ik", "solve_waypoints",
    "piecewise_linear", "fit_demonstration", "ProjectionReport", "project_demonstration",
    "add_servo", "add_servos", "dense_reference", "PDController", "track", "add_joint_equality",
    "add_force_sensor", "ForceSensor", "remove_static_load", "contact_force", "touching",
    "ContactPairs",
    "Recording", "load_recording", "save_recording", "find_contacts", "Contacts", "ContactInterval",
    "RecordedTask", "task_from_recording", "servo_controller",
    "Camera", "FrameRecorder", "caption", "write_side_by_side", "rendering_available", "make_renderer",
]
