"""Headless by default (corl.offscreen): without a display and without MUJOCO_GL, corl picks an
offscreen backend before MuJoCo is imported, keeps a user's own choice, and a run asked for a video
it cannot render says what to install instead of exiting 0 without it."""

from __future__ import annotations

import ctypes
import json
import os
import subprocess
import sys

import pytest

from corl import offscreen

HEADLESS = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY")}


def _loads(backend: str) -> bool:
    for name in offscreen.BACKENDS[backend]:
        try:
            ctypes.CDLL(name)
            return True
        except OSError:
            pass
    return False


def _python(code: str, **env) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**HEADLESS, **env},
                         timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip()


def test_importing_corl_headless_sets_the_first_backend_that_loads():
    expected = next((b for b in offscreen.BACKENDS if _loads(b)), None)
    code = "import os, sys, corl; print(os.environ.get('MUJOCO_GL'), 'mujoco' in sys.modules)"
    assert _python(code) == f"{expected} False"  # and MuJoCo itself is not imported


def test_a_users_choice_and_a_display_are_left_alone():
    code = "import os, corl; print(os.environ.get('MUJOCO_GL'))"
    assert _python(code, MUJOCO_GL="glfw") == "glfw"
    assert _python(code, DISPLAY=":99") == "None"  # a display: MuJoCo's own default (GLFW) renders


def test_a_headless_process_renders_without_mujoco_gl():
    if not any(_loads(b) for b in offscreen.BACKENDS):
        pytest.skip("neither libEGL nor libOSMesa on this machine")
    code = ("from corl.mujoco.video import ensure_rendering, make_renderer\n"
            "print(ensure_rendering())\n"
            "import mujoco, os\n"
            "m = mujoco.MjModel.from_xml_string(\"<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>\")\n"
            "r = make_renderer(m, height=8, width=8); r.update_scene(mujoco.MjData(m)); print(r.render().shape)\n"
            "print(os.environ['MUJOCO_GL'])")
    lines = _python(code).splitlines()
    assert lines[:2] == ["(True, '')", "(8, 8, 3)"] and lines[2] in offscreen.BACKENDS


def test_video_asked_for_and_impossible_is_one_line_and_exit_2(tmp_path):
    if _loads("osmesa"):
        pytest.skip("OSMesa loads here: MUJOCO_GL=osmesa would render")
    corl = os.path.join(os.path.dirname(sys.executable), "corl")
    out = subprocess.run([corl, "run", "door", "--video", "--out", str(tmp_path / "door")], capture_output=True,
                         text=True, env={**HEADLESS, "MUJOCO_GL": "osmesa"}, timeout=300)
    assert out.returncode == 2, out.stdout + out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "MUJOCO_GL=osmesa" in lines[0] and "apt-get install" in lines[0], lines
    assert "Traceback" not in out.stderr
    assert not (tmp_path / "door").exists()  # refused before any trial: nothing written, the folder removed


def test_the_probe_reports_why_a_backend_fails():
    why = offscreen._probe("no-such-backend")
    assert "MUJOCO_GL" in why or "invalid" in why.lower(), why
    assert json.dumps(why)  # one printable line
    assert "\n" not in why
