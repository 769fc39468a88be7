"""The live dashboard of ``corl serve`` in headless Chromium: it loads offline, draws the figures
``corl report`` draws, and a tell on the API shows up on the page within a second."""

from __future__ import annotations

import os
import re
import time
from importlib import resources

import numpy as np
import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from browser import Browser, chromium_path  # noqa: E402

from corl.client import Client  # noqa: E402
from corl.serve import background  # noqa: E402
from corl.tasks.registry import load_task  # noqa: E402


def test_the_dashboard_needs_no_network_beyond_its_server():
    static = resources.files("corl.serve") / "static"
    names = sorted(p.name for p in static.iterdir())
    assert names == ["dashboard.css", "dashboard.html", "dashboard.js"]
    for name in names:
        text = (static / name).read_text()
        assert not re.search(r"(https?:)?//[a-z0-9.-]+\.[a-z]{2,}", text, re.I), name  # no CDN, no font service


@pytest.mark.slow
def test_a_tell_shows_up_on_the_page_within_a_second(tmp_path):
    chromium_path()
    task = load_task("synthetic")
    with background(tmp_path / "s.corl", "synthetic") as url:
        c = Client(url, raw=True)
        steps = []
        while steps[-3:].count("reinforcement") < 3:  # into step 2: the return map exists
            trial = c.ask()
            c.tell(task.rollout(trial.w))
            steps.append(trial.step)
        told = len(steps)
        with Browser(tmp_path / "profile") as b:
            b.open(url + "/")
            assert b.wait_for(f"document.body.dataset.rows == '{told}'", timeout=30), "the trial table did not load"
            both = ("document.getElementById('fig-trials').naturalWidth > 0 && "
                    "document.getElementById('fig-return_map').naturalWidth > 0")
            assert b.wait_for(both, timeout=60), b.evaluate("document.body.innerText")[:500]
            assert b.evaluate("document.getElementById('trials').textContent") == str(told)
            delays = []
            for _ in range(3):
                trial = c.ask()
                outcome = task.rollout(trial.w)
                t0 = time.perf_counter()
                c.tell(outcome)
                shown = (f"document.getElementById('trials').textContent == '{trial.index + 1}' && "
                         f"document.querySelector('tr[data-trial=\"{trial.index}\"]').dataset.outcome == "
                         f"'{'success' if outcome.success else 'failure'}'")
                assert b.wait_for(shown, timeout=5), f"trial {trial.index} did not show up"
                delays.append(time.perf_counter() - t0)
            assert max(delays) < 1.0, delays
            shot = tmp_path / "dashboard.png"
            b.screenshot(shot)
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[1] == 1280 and img[..., :3].std() > 0.05  # drawn, not a blank page
    print(f"a tell shows up after {1e3 * np.max(delays):.0f} ms at most; screenshot: {shot}")


@pytest.mark.slow
def test_the_door_dashboard_shows_the_last_told_trial_rendered(tmp_path, monkeypatch):
    """The video comes from a process of its own that loads the task from the server's command line."""
    import urllib.request

    import imageio.v3 as iio

    chromium_path()
    monkeypatch.setenv("MUJOCO_GL", os.environ.get("MUJOCO_GL", "egl"))  # read by the video process at its start
    with background(tmp_path / "door.corl", "door", video=True) as url:
        c = Client(url)
        for value in (-1.0, -0.9):  # the demonstration, then the first optimization step
            trial = c.ask()
            assert trial.q.shape[1] == len(trial.joint_names) == 8
            c.tell(True, value)
        with Browser(tmp_path / "profile") as b:
            b.open(url + "/")
            src = b.wait_for("document.getElementById('video').src.includes('/video') && "
                             "document.getElementById('video-caption').textContent.includes('trial 1') && "
                             "document.getElementById('video').src", timeout=120)
            assert src, b.evaluate("document.getElementById('video-caption').textContent")
        data = urllib.request.urlopen(url + "/video", timeout=30).read()
    (tmp_path / "last.mp4").write_bytes(data)
    frame = iio.imread(tmp_path / "last.mp4", index=20)
    assert frame.ndim == 3 and frame.std() > 10  # a rendered scene, not a blank frame
