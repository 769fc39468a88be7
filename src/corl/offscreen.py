"""Headless by default: an offscreen OpenGL backend for MuJoCo, chosen before MuJoCo is imported.

MuJoCo reads ``MUJOCO_GL`` once, when ``import mujoco`` runs, and without it and without a display
it picks GLFW, which cannot render on a server. :func:`choose` runs when corl is imported: on a
Linux machine with no display and no ``MUJOCO_GL`` it sets ``MUJOCO_GL`` to the first backend whose
library loads (EGL, else OSMesa), as other MuJoCo tools do. A user's own ``MUJOCO_GL`` is never
changed. :func:`ensure` goes further where a video is asked for (``corl run --video``, ``corl serve``,
``corl report``): it renders one tiny frame with each candidate in a fresh process and keeps the
first that works, since a library that loads may still fail to make a context.

Nothing here imports MuJoCo (``import corl`` stays light); the probe runs in a child process.
"""

from __future__ import annotations

import ctypes
import os
import subprocess
import sys

__all__ = ["BACKENDS", "INSTALL_HINT", "choose", "chosen_by_corl", "ensure", "headless"]

#: Offscreen backends in the order they are tried, with the shared libraries each one loads.
BACKENDS = {"egl": ("libEGL.so.1", "libEGL.so"), "osmesa": ("libOSMesa.so.8", "libOSMesa.so.6", "libOSMesa.so")}
#: What to install when no backend works (one line, said by every command that renders).
INSTALL_HINT = ("install EGL (Debian/Ubuntu: apt-get install libegl1 libgl1-mesa-dri) or OSMesa "
                "(apt-get install libosmesa6), or set MUJOCO_GL to a backend that works here")

_PROBE = ("import mujoco\n"
          "m = mujoco.MjModel.from_xml_string(\"<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>\")\n"
          "r = mujoco.Renderer(m, height=8, width=8)\n"
          "d = mujoco.MjData(m)\n"
          "r.update_scene(d)\n"
          "r.render()\n"
          "r.close()\n")
_CHOSEN: str | None = None  # the backend corl set MUJOCO_GL to (None: corl set nothing)


def headless() -> bool:
    """True on Linux with no X or Wayland display: where MuJoCo's default (GLFW) cannot render."""
    return sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _loads(backend: str) -> bool:
    for name in BACKENDS[backend]:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            continue
    return False


def chosen_by_corl() -> str | None:
    """The backend :func:`choose` or :func:`ensure` set ``MUJOCO_GL`` to, None when corl set nothing."""
    return _CHOSEN if _CHOSEN is not None and os.environ.get("MUJOCO_GL") == _CHOSEN else None


def _settable() -> bool:
    """corl may set MUJOCO_GL: headless, MuJoCo not imported yet, and the variable unset or corl's own."""
    own = "MUJOCO_GL" not in os.environ or chosen_by_corl() is not None
    return own and headless() and "mujoco" not in sys.modules


def choose() -> str | None:
    """Set ``MUJOCO_GL`` to the first backend whose library loads, when corl may (see :func:`_settable`).

    Returns the backend set, or None (a display, the user's own ``MUJOCO_GL``, MuJoCo already
    imported, or no library found).
    """
    global _CHOSEN
    if not _settable() or "MUJOCO_GL" in os.environ:
        return None
    for backend in BACKENDS:
        if _loads(backend):
            os.environ["MUJOCO_GL"] = _CHOSEN = backend
            return backend
    return None


def _probe(backend: str | None, timeout: float = 60.0) -> str:
    """Render one 8x8 frame in a fresh process with ``MUJOCO_GL=backend`` (None: as the environment
    says); "" when it worked, else the last line of its error."""
    env = dict(os.environ)
    if backend is not None:
        env["MUJOCO_GL"] = backend
    try:
        out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env,
                             timeout=timeout, stdin=subprocess.DEVNULL)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{type(exc).__name__}: {exc}"
    if out.returncode == 0:
        return ""
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    return lines[-1].strip() if lines else f"exit {out.returncode}"


def ensure() -> tuple[bool, str]:
    """Make sure this process can render offscreen, before MuJoCo is imported; ``(ok, why not)``.

    With the user's own ``MUJOCO_GL``, or a display, that setting is tried and kept. Headless and
    unset (or set by corl), EGL then OSMesa are tried in a fresh process each, and ``MUJOCO_GL`` is
    set to the first that renders. Once MuJoCo is imported the choice is made, and a fresh process
    says how it renders, not whether this one can: that is tried only in this process, which :func:`corl.mujoco.video.ensure_rendering` does.
    """
    global _CHOSEN
    if not _settable():
        why = _probe(None)
        where = f"MUJOCO_GL={os.environ['MUJOCO_GL']}" if "MUJOCO_GL" in os.environ else "this display"
        return (True, "") if not why else (False, f"cannot render offscreen with {where} ({why}): {INSTALL_HINT}")
    reasons = []
    for backend in BACKENDS:
        why = _probe(backend) if _loads(backend) else f"no {BACKENDS[backend][0]}"
        if not why:
            os.environ["MUJOCO_GL"] = _CHOSEN = backend
            return True, ""
        reasons.append(f"{backend}: {why}")
    if chosen_by_corl() is not None:  # what choose() set does not work: leave MuJoCo its default
        del os.environ["MUJOCO_GL"]
        _CHOSEN = None
    return False, f"cannot render offscreen without a display ({'; '.join(reasons)}): {INSTALL_HINT}"
