"""The kit's video: fast renderer settings that leave the model as it was, and the side-by-side file."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from corl.mujoco.video import SAMPLES, SHADOW_SIZE, write_side_by_side

mujoco = pytest.importorskip("mujoco")
imageio = pytest.importorskip("imageio.v2")

SCENE = "<mujoco><worldbody><light pos='0 0 2'/><geom type='plane' size='1 1 .1'/><geom size='.1' pos='0 0 .2'/></worldbody></mujoco>"


def test_renderer_settings_do_not_change_the_model():
    # MuJoCo reads MUJOCO_GL once per process: check in a fresh one, with EGL
    code = (
        "import mujoco\n"
        "from corl.mujoco.video import make_renderer, rendering_available, SHADOW_SIZE\n"
        f"m = mujoco.MjModel.from_xml_string({SCENE!r})\n"
        "ok, why = rendering_available()\n"
        "if not ok: print('SKIP', why); raise SystemExit\n"
        "before = (m.vis.quality.shadowsize, m.vis.quality.offsamples)\n"
        "r = make_renderer(m, height=48, width=64)\n"
        "d = mujoco.MjData(m); mujoco.mj_forward(m, d); r.update_scene(d); img = r.render()\n"
        "assert (m.vis.quality.shadowsize, m.vis.quality.offsamples) == before, before\n"
        "assert img.shape == (48, 64, 3) and img.std() > 1.0\n"
        "r.close(); print('OK', before)\n"
    )
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)
    if out.stdout.startswith("SKIP"):
        pytest.skip(out.stdout)
    assert out.returncode == 0 and out.stdout.startswith("OK"), out.stdout + out.stderr[-2000:]
    assert SHADOW_SIZE < 4096 and SAMPLES >= 0  # below MuJoCo's defaults (4096, 4): what made frames slow


def test_side_by_side_holds_the_shorter_clip_and_keeps_both_halves(tmp_path):
    left = np.zeros((5, 48, 64, 3), dtype=np.uint8)
    left[..., 0] = 200  # red
    right = np.zeros((3, 48, 64, 3), dtype=np.uint8)
    right[..., 2] = 200  # blue
    path = write_side_by_side(tmp_path / "both.mp4", left, right, fps=10)
    frames = np.stack(imageio.mimread(path))
    assert frames.shape[0] == 5 and frames.shape[2] == 128  # the longer clip's length, both widths
    last = frames[-1].astype(float)
    assert last[:, :64, 0].mean() > 150 and last[:, :64, 2].mean() < 60  # left stays red
    assert last[:, 64:, 2].mean() > 150 and last[:, 64:, 0].mean() < 60  # right holds its last (blue) frame
