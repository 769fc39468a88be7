"""Videos of door trials: MuJoCo's offscreen renderer (``MUJOCO_GL=egl`` on a CPU machine).

:func:`render_rollout` returns frames of one trial; :func:`write_side_by_side` puts two trials
(the demonstration and the learned motion) next to each other in one MP4 (or GIF) file.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["render_rollout", "write_side_by_side", "caption"]


def _camera(scene):
    import mujoco

    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    # from the robot's front right, slightly above: the hand on the handle and the door's swing
    cam.lookat[:] = np.asarray(scene.pivot_world) + np.array([-0.1, 0.0, 0.0])
    cam.distance = 1.3
    cam.azimuth = -60.0
    cam.elevation = -25.0
    return cam


def render_rollout(reference, *, duration: float = 5.0, t_contact=None, fps: int = 25,
                   width: int = 480, height: int = 360, label: str = ""):
    """Simulate ``reference`` and return ``(frames (F, height, width, 3) uint8, RolloutResult)``."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import mujoco

    from corl.tasks.door.scene import load_scene
    from corl.tasks.door.sim import rollout

    scene = load_scene()
    renderer = mujoco.Renderer(scene.model, height=height, width=width)
    cam = _camera(scene)
    frames = []

    def grab(t, data):
        renderer.update_scene(data, camera=cam)
        frames.append(renderer.render().copy())

    every = max(1, int(round(1.0 / (fps * scene.model.opt.timestep))))
    try:
        result = rollout(reference, duration=duration, t_contact=t_contact, scene=scene,
                         on_frame=grab, frame_every=every)
    finally:
        renderer.close()
    frames = np.stack(frames)
    if label:
        frames = caption(frames, label)
    return frames, result


def caption(frames: np.ndarray, text: str) -> np.ndarray:
    """Burn a caption into the top-left corner of every frame (matplotlib's font rasteriser)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    h = 28
    fig = Figure(figsize=(frames.shape[2] / 100, h / 100), dpi=100)
    canvas = FigureCanvasAgg(fig)
    fig.patch.set_facecolor("black")
    fig.text(0.01, 0.5, text, color="white", va="center", fontsize=11)
    canvas.draw()
    banner = np.asarray(canvas.buffer_rgba())[:, :, :3]
    out = frames.copy()
    out[:, : banner.shape[0], : banner.shape[1]] = banner[: out.shape[1], : out.shape[2]]
    return out


def write_side_by_side(path: str | os.PathLike, left: np.ndarray, right: np.ndarray, fps: int = 25) -> Path:
    """Write two frame stacks next to each other; MP4 when ffmpeg is available, else GIF."""
    import imageio.v2 as imageio

    n = max(len(left), len(right))
    pad = lambda f: np.concatenate([f, np.repeat(f[-1:], n - len(f), axis=0)]) if len(f) < n else f  # noqa: E731
    both = np.concatenate([pad(left), pad(right)], axis=2)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        imageio.mimwrite(path, list(both), fps=fps, macro_block_size=8)
    except Exception:
        path = path.with_suffix(".gif")
        imageio.mimwrite(path, list(both), duration=1.0 / fps)
    return path
