"""``corl run --video``: the video is rendered once, after learning and after the store is closed;
without ``--video`` nothing renders and the summary says how to get one."""

from __future__ import annotations

import json
import textwrap
import uuid

import pytest
from typer.testing import CliRunner

from corl.cli import app

MODULE = '''
import json
from pathlib import Path

import numpy as np

from corl.store import RunStore
from corl.tasks.synthetic import SyntheticTask

CALLS = Path("render_calls.json")


class Rendering(SyntheticTask):
    """The synthetic task with a render_comparison that records when and how it was called."""

    def render_comparison(self, w_demo, w_learned, path):
        from corl.mujoco.video import write_side_by_side

        with RunStore(Path(path).parent / "run.corl"):  # the writer lock is free: the run is closed
            pass
        calls = json.loads(CALLS.read_text()) if CALLS.exists() else []
        CALLS.write_text(json.dumps(calls + [[float(np.abs(w_learned - w_demo).max())]]))
        frames = np.zeros((3, 16, 16, 3), dtype=np.uint8)
        return str(write_side_by_side(path, frames, frames + 255, fps=5))


class Broken(Rendering):
    """A task whose renderer fails once the run is over (as a GPU driver might)."""

    def render_comparison(self, w_demo, w_learned, path):
        raise RuntimeError("the OpenGL context was lost")


def make_task():
    return Rendering()


def make_broken():
    return Broken()
'''


@pytest.fixture
def module(tmp_path, monkeypatch):
    name = f"rendertask_{uuid.uuid4().hex[:8]}"
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(MODULE))
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    return name


def run(*args):
    res = CliRunner().invoke(app, ["run", *map(str, args), "--method", "CMA", "--quiet", "--json"])
    assert res.exit_code == 0, res.output
    return json.loads(res.stdout)


def test_no_video_unless_asked(module, tmp_path):
    summary = run(f"{module}:make_task", "--out", tmp_path / "a")
    assert "video" not in summary["files"]
    assert "--video" in summary["files"]["video_skipped"]
    assert not (tmp_path / "render_calls.json").exists()  # nothing rendered
    assert not list((tmp_path / "a").glob("*.mp4")) and not list((tmp_path / "a").glob("*.gif"))


def test_video_once_after_the_store_is_closed(module, tmp_path):
    summary = run(f"{module}:make_task", "--out", tmp_path / "b", "--video")
    calls = json.loads((tmp_path / "render_calls.json").read_text())
    assert len(calls) == 1 and calls[0][0] > 0  # once, demonstration against the learned motion
    video = tmp_path / "b" / summary["files"]["video"].split("/")[-1]
    assert video.is_file() and video.stat().st_size > 0
    on_disk = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert on_disk["files"]["video"] == summary["files"]["video"]


def test_a_video_asked_for_and_not_made_is_no_success(module, tmp_path):
    res = CliRunner().invoke(app, ["run", f"{module}:make_broken", "--out", str(tmp_path / "c"), "--method", "CMA",
                                   "--quiet", "--video"])
    assert res.exit_code == 2, res.output  # never exit 0 without the video asked for
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and "the OpenGL context was lost" in lines[0] and "corl report" in lines[0]
    summary = json.loads((tmp_path / "c" / "summary.json").read_text())  # the run's results are kept
    assert "the OpenGL context was lost" in summary["files"]["video_skipped"] and summary["trials"] > 1
