"""Forward kinematics of the contact point and inverse kinematics of the PR2 right arm, on
:mod:`corl.mujoco`.

Glossary
--------
q          (8,) the 7 arm joint angles (rad), then the gripper opening width (m)
phi_CP(q)  (3,) world position of the contact point: the midpoint of the two fingertip pads
           (the contact point of Eq. 6)
J_CP(q)    (3, 8) its Jacobian d phi_CP / d q; the width column is analytic (finger angle
           chain rule through the joint equalities, :class:`corl.mujoco.Gripper`)
R_hand(q)  (3, 3) orientation of the palm frame (x: approach, y: finger opening direction)
"""

from __future__ import annotations

import numpy as np

from corl.mujoco import Kinematics as _Kinematics
from corl.mujoco import Target, rotation_error, solve_ik
from corl.tasks.door.scene import WRIST_BODY, DoorScene, load_scene

__all__ = ["Kinematics", "rotation_error"]


class Kinematics(_Kinematics):
    """The kit's :class:`corl.mujoco.Kinematics` of the door scene's robot, with the contact
    point (``pads``: the two fingertip pad sites) and the palm (``hand``: the wrist roll link).

    Parameters
    ----------
    scene : DoorScene, optional
        Defaults to the cached :func:`load_scene`.
    """

    def __init__(self, scene: DoorScene | None = None):
        self.scene = scene or load_scene()
        super().__init__(self.scene.robot)
        self.pads = self.site("pad_l", "pad_r")
        self.hand = self.body(WRIST_BODY)

    def contact_point(self, q: np.ndarray) -> np.ndarray:
        """phi_CP(q): world position (3,) of the midpoint between the fingertip pads."""
        return self.position(q, self.pads)

    def hand_rotation(self, q: np.ndarray) -> np.ndarray:
        """R_hand(q): (3, 3) palm orientation (columns: approach, opening, normal)."""
        return self.rotation(q, self.hand)

    def contact_point_jacobian(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """phi_CP(q) (3,) and J_CP(q) (3, 8)."""
        return self.position_jacobian(q, self.pads)

    def ik(self, target_pos: np.ndarray, target_rot: np.ndarray | None, q_init: np.ndarray, *,
           rot_weight: float = 0.3, damping: float = 1e-3, iterations: int = 200,
           tol: float = 1e-5) -> np.ndarray:
        """Put the contact point at ``target_pos`` (3,) and the palm at ``target_rot`` (3, 3) or
        anywhere (None), from ``q_init`` (8,) keeping its width: :func:`corl.mujoco.solve_ik`."""
        return solve_ik(self, self.pads, Target(target_pos, target_rot), q_init, rotation_frame=self.hand,
                        rot_weight=rot_weight, damping=damping, iterations=iterations, tol=tol)
