"""Videos of door trials with the kit's offscreen renderer (``MUJOCO_GL=egl`` on a CPU machine).

:func:`render_rollout` returns frames of one trial; :func:`corl.mujoco.write_side_by_side` puts two
trials (the demonstration and the learned motion) next to each other in one MP4 (or GIF) file.
"""

from __future__ import annotations

import numpy as np

from corl.mujoco import Camera, FrameRecorder, caption
from corl.mujoco import write_side_by_side as _write_side_by_side

__all__ = ["render_rollout", "write_side_by_side", "caption", "door_camera", "FPS", "SHADOW_SIZE"]

#: Frames per second of the door's videos: 101 frames for a 5 s trial (smooth for a slow door), 20 %
#: fewer than at 25 fps, so the demonstration beside the learned motion renders in about 2 s.
FPS = 20
#: The door's shadow map (pixels): 512 costs 10 ms a frame on a CPU renderer against 14 ms at the
#: kit's 1024; the scene has no floor, and at 480x360 the shadows on the door look the same.
SHADOW_SIZE = 512


def door_camera(scene) -> Camera:
    """From the robot's front right, slightly above: the hand on the handle and the door's swing."""
    return Camera(lookat=tuple(np.asarray(scene.pivot_world) + np.array([-0.1, 0.0, 0.0])), distance=1.3,
                  azimuth=-60.0, elevation=-25.0)


def write_side_by_side(path, left: np.ndarray, right: np.ndarray, fps: int = FPS):
    """:func:`corl.mujoco.write_side_by_side` at the door's frame rate."""
    return _write_side_by_side(path, left, right, fps=fps)


def render_rollout(reference, *, duration: float = 5.0, t_contact=None, fps: int = FPS,
                   width: int = 480, height: int = 360, label: str = "", scene=None):
    """Simulate ``reference`` in ``scene`` (default: the unmoved door's) and return
    ``(frames (F, height, width, 3) uint8, RolloutResult)``."""
    from corl.tasks.door.scene import load_scene
    from corl.tasks.door.sim import rollout

    scene = scene or load_scene()
    recorder = FrameRecorder(scene.model, door_camera(scene), fps=fps, width=width, height=height,
                             shadow_size=SHADOW_SIZE)
    try:
        result = rollout(reference, duration=duration, t_contact=t_contact, scene=scene,
                         on_frame=lambda t, data: recorder.grab(data), frame_every=recorder.every)
    finally:
        frames = recorder.close()
    if label:
        frames = caption(frames, label)
    return frames, result
