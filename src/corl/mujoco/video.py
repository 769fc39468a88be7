"""Offscreen video of a rollout: MuJoCo's renderer, headless by default.

MuJoCo reads ``MUJOCO_GL`` once, when it is first imported, and then fails to import at all if
that backend's library is missing. ``import corl`` picks an offscreen backend on a machine without
a display when ``MUJOCO_GL`` is unset (:mod:`corl.offscreen`: EGL, else OSMesa); a user's own
``MUJOCO_GL`` is kept. :func:`ensure_rendering` checks that rendering works before a command that
was asked for a video does any work; a renderer that still cannot be made raises.

:class:`FrameRecorder` is an ``on_step`` hook for :func:`corl.mujoco.track` that grabs frames at a
given rate; :func:`caption` burns a caption in; :func:`write_side_by_side` puts two trials (the
demonstration and the learned motion) next to each other in one MP4 (GIF without ffmpeg).
:func:`rendering_available` says whether this process can render at all; :func:`make_renderer`
makes a renderer or raises, without the warnings and the stray traceback MuJoCo prints when it cannot.
"""

from __future__ import annotations

import gc
import os
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from corl import offscreen

__all__ = ["Camera", "FrameRecorder", "caption", "write_side_by_side", "rendering_available", "make_renderer",
           "ensure_rendering", "RENDERING_HINT"]

#: What to do when no offscreen OpenGL context can be made (said wherever a video is skipped).
RENDERING_HINT = f"To render offscreen, {offscreen.INSTALL_HINT}"

#: Shadow-map size (pixels) of the kit's renderers. MuJoCo's default, 4096, is what a CPU renderer
#: (Mesa's llvmpipe under EGL) spends most of a frame on: the door's 480x360 frame took 95 ms at
#: 4096 and 13 ms at 1024, with no difference visible at that resolution.
SHADOW_SIZE = 1024
#: Multisampling of the offscreen buffer (MuJoCo's default is 4): 2x the cost of a frame on a CPU
#: renderer, for smoother edges. 0 keeps videos fast; pass ``samples=4`` for a figure.
SAMPLES = 0
#: ffmpeg's x264 preset: "veryfast" encodes the door's side-by-side video in 0.3 s against 0.7 s at
#: the default ("medium"), about 10 % larger.
X264_PRESET = "veryfast"


@dataclass(frozen=True)
class Camera:
    """A free camera looking at ``lookat`` (3,) from ``distance`` m, ``azimuth`` and ``elevation`` deg."""

    lookat: tuple = (0.0, 0.0, 0.5)
    distance: float = 1.5
    azimuth: float = -60.0
    elevation: float = -25.0

    def mjv(self):
        """This camera as a ``mujoco.MjvCamera``."""
        import mujoco

        cam = mujoco.MjvCamera()
        cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        cam.lookat[:] = np.asarray(self.lookat, dtype=float)
        cam.distance, cam.azimuth, cam.elevation = self.distance, self.azimuth, self.elevation
        return cam


def _quiet_half_made_renderer(hook):
    """An ``unraisablehook`` that drops the error of a half-made renderer's ``__del__`` only."""
    def quiet(unraisable) -> None:
        if getattr(unraisable.object, "__qualname__", "") != "Renderer.__del__":
            hook(unraisable)
    return quiet


def make_renderer(model, *, height: int, width: int, shadow_size: int | None = SHADOW_SIZE,
                  samples: int | None = SAMPLES):
    """``mujoco.Renderer(model, height, width)``, or the reason it cannot be made, quietly.

    ``shadow_size`` and ``samples`` (None: the model's own ``<visual><quality shadowsize offsamples>``)
    set the renderer's shadow map and multisampling; the model is left as it was (MuJoCo reads
    both once, when the renderer's context is made).

    Without a display and without ``MUJOCO_GL``, MuJoCo tries GLFW: GLFW warns (``GLFWError``),
    ``Renderer`` raises, and the half-made renderer's ``__del__`` prints a traceback when it is
    collected. Here the warnings are kept in, the collection happens at once with only that
    ``__del__``'s error dropped, and the original error is raised again, free of the renderer.
    A second attempt after such a failure aborts the whole process inside MuJoCo (SIGABRT,
    "recursive initialization"), so the first failure is remembered and raised again instead. A
    size larger than the model's offscreen buffer is refused first, and never remembered.
    """
    import mujoco

    global _RENDER_FAILED
    width_max, height_max = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
    if not (0 < int(width) <= width_max and 0 < int(height) <= height_max):
        raise ValueError(f"a {width}x{height} image does not fit this model's offscreen buffer "
                         f"({width_max}x{height_max}); render smaller or raise <visual><global "
                         "offwidth=... offheight=...> in the model")
    if _RENDER_FAILED is not None:
        raise _error(*_RENDER_FAILED)
    kind = message = None
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_half_made_renderer(hook)
    quality = model.vis.quality
    kept = (int(quality.shadowsize), int(quality.offsamples))
    try:
        if shadow_size is not None:
            quality.shadowsize = int(shadow_size)
        if samples is not None:
            quality.offsamples = int(samples)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            try:
                return mujoco.Renderer(model, height=height, width=width)
            except Exception as exc:  # no EGL / OSMesa library, no display, or no GPU driver
                kind, message = type(exc), str(exc)
        gc.collect()  # the half-made renderer goes now, while its __del__'s error is dropped
    finally:
        sys.unraisablehook = hook
        quality.shadowsize, quality.offsamples = kept
    if not issubclass(kind, (ValueError, TypeError)):  # an argument error never made an OpenGL context
        _RENDER_FAILED = (kind, message)
    raise _error(kind, message)


_RENDER_FAILED: tuple[type, str] | None = None  # (type, message) of this process's failed renderer


def _error(kind: type, message: str) -> Exception:
    try:
        return kind(message)
    except Exception:
        return RuntimeError(f"{kind.__name__}: {message}")


def rendering_available() -> tuple[bool, str]:
    """``(True, "")`` when an offscreen OpenGL context can be made, else ``(False, reason)``."""
    try:
        import mujoco

        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>")
        make_renderer(model, height=8, width=8).close()
    except Exception as exc:  # no EGL / OSMesa library, or no GPU driver
        return False, f"{type(exc).__name__}: {exc}. {RENDERING_HINT}"
    return True, ""


def ensure_rendering() -> tuple[bool, str]:
    """``(True, "")`` when this process can render (choosing a backend first if MuJoCo is not imported
    yet: :func:`corl.offscreen.ensure`), else ``(False, one line that says what to install)``."""
    if "mujoco" not in sys.modules:
        return offscreen.ensure()
    return rendering_available()


class FrameRecorder:
    """Grab frames of a simulation: call it as ``on_step(k, data)``; close it when done.

    Parameters
    ----------
    model : mujoco.MjModel
    camera : Camera
    fps : frames per second of simulated time
    width, height : pixels
    shadow_size, samples : the renderer's shadow map and multisampling (:func:`make_renderer`)
    """

    def __init__(self, model, camera: Camera, *, fps: int = 25, width: int = 480, height: int = 360,
                 shadow_size: int | None = SHADOW_SIZE, samples: int | None = SAMPLES) -> None:
        self.renderer = make_renderer(model, height=height, width=width, shadow_size=shadow_size, samples=samples)
        self.camera = camera.mjv()
        self.every = max(1, int(round(1.0 / (fps * model.opt.timestep))))
        self.frames: list[np.ndarray] = []

    def grab(self, data) -> None:
        """Render ``data`` now."""
        self.renderer.update_scene(data, camera=self.camera)
        self.frames.append(self.renderer.render().copy())

    def __call__(self, k: int, data) -> None:
        if k % self.every == 0:
            self.grab(data)

    def close(self) -> np.ndarray:
        """Free the renderer; the frames (F, height, width, 3) uint8."""
        self.renderer.close()
        return np.stack(self.frames) if self.frames else np.zeros((0, 1, 1, 3), dtype=np.uint8)

    def __enter__(self) -> "FrameRecorder":
        return self

    def __exit__(self, *exc) -> None:
        self.renderer.close()


def caption(frames: np.ndarray, text: str) -> np.ndarray:
    """Burn ``text`` into the top-left corner of every frame (F, H, W, 3) (matplotlib's rasteriser)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

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
    """Write two frame stacks (F, H, W, 3) next to each other; MP4 when ffmpeg is there, else GIF.

    The shorter stack holds its last frame. Frames go to the encoder one by one (no copy of the
    whole video in memory), into a hidden ``.partial`` file renamed to ``path`` once complete: a
    failed encoding never leaves a truncated video under the promised name.
    """
    import imageio.v2 as imageio

    n = max(len(left), len(right))

    def frames():
        for i in range(n):
            yield np.concatenate([left[min(i, len(left) - 1)], right[min(i, len(right) - 1)]], axis=1)

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.partial{path.suffix}")  # renamed into place once complete
    try:
        with imageio.get_writer(partial, fps=fps, macro_block_size=8, ffmpeg_params=["-preset", X264_PRESET]) as out:
            for frame in frames():
                out.append_data(frame)
        os.replace(partial, path)
    except Exception:
        partial.unlink(missing_ok=True)
        path = path.with_suffix(".gif")
        partial = path.with_name(f".{path.stem}.partial.gif")
        try:
            imageio.mimwrite(partial, list(frames()), duration=1.0 / fps)
            os.replace(partial, path)
        finally:
            partial.unlink(missing_ok=True)
    return path
