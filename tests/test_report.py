"""`corl report`: self-contained HTML pages of stored runs (corl/experiments/html/report.py, page.py)."""

import base64
import io
import json
import os
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.experiments.html.report import _existing_video
from corl.session import StoredRun
from corl.store import RunStore
from corl.tasks.registry import load_task

runner = CliRunner()


class _Page(HTMLParser):
    """Collects the attributes that load something, the <img> sources and the trial table's rows."""

    def __init__(self):
        super().__init__()
        self.links, self.images, self.trial_rows, self.body = [], [], 0, {}
        self._in_trials = self._in_tbody = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        for key in ("src", "href", "poster", "data", "action"):
            if key in attrs:
                self.links.append((tag, key, attrs[key]))
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        if tag == "body":
            self.body = attrs
        if tag == "table" and "trials" in (attrs.get("class") or "").split():
            self._in_trials = True
        if tag == "tbody" and self._in_trials:
            self._in_tbody = True
        if tag == "tr" and self._in_tbody:
            self.trial_rows += 1

    def handle_endtag(self, tag):
        if tag == "table":
            self._in_trials = self._in_tbody = False


def parse(path):
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


@pytest.fixture(scope="module")
def synthetic_run(tmp_path_factory):
    """A finished synthetic run (seed 2: 221 trials, two failures, < 1 s) and its number of trials."""
    store = tmp_path_factory.mktemp("run") / "run.corl"
    task = load_task("synthetic", seed=2)
    with RunStore(store) as db:
        run = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=2)
        run.run(task)
        assert run.done
        return store, len(run.history)


def report(store, out, *args, task="synthetic"):
    """`corl report --quiet`, naming the task like `corl run` did (``task=None``: no --task)."""
    named = [] if task is None else ["--task", task]
    return runner.invoke(app, ["report", "--store", str(store), "--out", str(out), "--quiet", *named, *args])


def test_page_is_self_contained_with_every_trial_and_png_figures(synthetic_run, tmp_path):
    import matplotlib.image as mpimg

    store, n_trials = synthetic_run
    res = report(store, tmp_path / "rep")
    assert res.exit_code == 0, res.output
    page_path = tmp_path / "rep" / "run_1.html"
    assert res.stdout.strip() == str(page_path)
    page = parse(page_path)
    text = page_path.read_text(encoding="utf-8")
    # nothing is fetched: every src/href is a data: URI (or an in-page anchor), no URL anywhere in CSS
    assert page.links and all(v.startswith("data:") or v.startswith("#") for _, _, v in page.links), page.links
    assert not re.search(r"https?://|url\(|<link\b|@import", text)
    assert page.trial_rows == n_trials > 100
    # the learning curves, Fig. 2b and the return map, each a real PNG with something drawn
    assert len(page.images) == 3
    for uri in page.images:
        assert uri.startswith("data:image/png;base64,")
        raw = base64.b64decode(uri.split(",", 1)[1], validate=True)
        assert raw[:8] == b"\x89PNG\r\n\x1a\n"
        img = mpimg.imread(io.BytesIO(raw), format="png")
        assert img.shape[0] > 300 and img.shape[1] > 400 and img[..., :3].std() > 0.05
    for piece in ("Configuration", "task spec", "eps_max", "numpy", "Return map", 'class="best"', "FAILURE"):
        assert piece in text, piece
    assert "Not shown" not in text  # the learner was rebuilt by replay, nothing is missing


def test_every_run_gets_a_page_and_a_pending_trial_shows(synthetic_run, tmp_path):
    store = tmp_path / "two.corl"
    shutil.copy(synthetic_run[0], store)
    task = load_task("synthetic", seed=1)
    with RunStore(store) as db:
        second = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=1)
        second.run(task, max_trials=20)
        second.ask()  # handed out, never told
    res = report(store, tmp_path / "all")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "all").iterdir()) == ["index.html", "run_1.html", "run_2.html"]
    assert parse(tmp_path / "all" / "run_2.html").trial_rows == 21
    assert 'class="pending"' in (tmp_path / "all" / "run_2.html").read_text()
    index = parse(tmp_path / "all" / "index.html")
    assert [v for _, _, v in index.links] == ["run_1.html", "run_2.html"]
    res = report(store, tmp_path / "one", "--run", "2")
    assert res.exit_code == 0 and [p.name for p in (tmp_path / "one").iterdir()] == ["run_2.html"]


def test_video_beside_the_store_is_embedded_unless_no_video(synthetic_run, tmp_path):
    store = tmp_path / "run.corl"
    shutil.copy(synthetic_run[0], store)
    fake_mp4 = b"\x00\x00\x00\x18ftypmp42" + bytes(range(64))
    (tmp_path / "demo_vs_learned.mp4").write_bytes(fake_mp4)
    summary = {"run_id": 1, "files": {"video": "/elsewhere/demo_vs_learned.mp4"}}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    assert report(store, tmp_path / "v").exit_code == 0
    text = (tmp_path / "v" / "run_1.html").read_text()
    assert "data:video/mp4;base64," + base64.b64encode(fake_mp4).decode() in text and "<video" in text
    assert report(store, tmp_path / "nv", "--no-video").exit_code == 0
    assert "<video" not in (tmp_path / "nv" / "run_1.html").read_text()
    assert _existing_video(store, 1, n_runs=1) == tmp_path / "demo_vs_learned.mp4"
    summary["run_id"] = 7  # the video shows another run: not this one's
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    assert _existing_video(store, 1, n_runs=1) is None
    (tmp_path / "summary.json").unlink()  # no summary: the video is the run's only if the store has one run
    assert _existing_video(store, 1, n_runs=1) == tmp_path / "demo_vs_learned.mp4"
    assert _existing_video(store, 1, n_runs=2) is None


@pytest.mark.parametrize("case, message", [("missing", "no store at"), ("run", "has no run 9"),
                                           ("damaged", "damaged"), ("empty", "nothing to report")])
def test_bad_input_is_one_line_and_exit_2(synthetic_run, tmp_path, case, message):
    store, args = synthetic_run[0], []
    if case == "missing":
        store = tmp_path / "nope.corl"
    elif case == "run":
        args = ["--run", "9"]
    elif case == "damaged":
        store = tmp_path / "bad.corl"
        store.write_bytes(np.random.default_rng(0).bytes(4096))
    else:
        store = tmp_path / "empty.corl"
        RunStore(store).close()
    res = report(store, tmp_path / "out", *args)
    assert res.exit_code == 2, res.output
    assert message in res.stderr and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert res.stderr.startswith("error: ")


def _chromium():
    from browser import chromium_path

    return chromium_path()


def _browser(chromium, tmp_path, *args):
    profile = tmp_path / f"profile{len(list(tmp_path.glob('profile*')))}"
    profile.mkdir()
    cmd = [chromium, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--hide-scrollbars", f"--user-data-dir={profile}", "--virtual-time-budget=10000", *args]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, res.stderr[-2000:]
    return res.stdout


@pytest.mark.slow
def test_page_renders_in_headless_chromium(synthetic_run, tmp_path):
    import matplotlib.image as mpimg

    chromium = _chromium()
    assert report(synthetic_run[0], tmp_path / "rep").exit_code == 0
    page = tmp_path / "rep" / "run_1.html"
    dom = _browser(chromium, tmp_path, "--dump-dom", page.as_uri())
    body = parse_dom_body(dom)
    # the page's load handler counted the images that decoded (naturalWidth > 0)
    assert body.get("data-images-total") == "3" and body.get("data-images-loaded") == "3", body
    shot = tmp_path / "screenshot.png"
    _browser(chromium, tmp_path, "--window-size=1280,2400", f"--screenshot={shot}", page.as_uri())
    img = mpimg.imread(shot)
    assert img.shape[:2] == (2400, 1280)
    assert img[..., :3].std() > 0.05  # drawn, not a blank page
    print(f"screenshot: {shot}")


def parse_dom_body(dom: str) -> dict:
    page = _Page()
    page.feed(dom)
    return page.body


def test_a_task_that_cannot_be_loaded_is_refused_and_another_task_is_a_note(tmp_path, monkeypatch):
    store = tmp_path / "custom.corl"
    task = load_task("synthetic", seed=2)
    with RunStore(store) as db:
        run = StoredRun.start(db, task, task_spec="synthetic", method="CORL+PIBU", seed=2)
        run.run(task, max_trials=12)
    res = report(store, tmp_path / "rep", task="no_such_module_here:make_task")
    assert res.exit_code == 2 and "cannot import task module 'no_such_module_here'" in res.stderr, res.output
    assert not (tmp_path / "rep").exists()  # refused: no folder left behind
    (tmp_path / "other.py").write_text("from corl.tasks.synthetic import SyntheticTask\n"
                                       "class Other(SyntheticTask):\n    name = 'other'\n"
                                       "def make():\n    return Other((0.6, 0.4))\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    res = report(store, tmp_path / "rep", task="other:make")
    sys.modules.pop("other", None)
    assert res.exit_code == 0, res.output
    text = (tmp_path / "rep" / "run_1.html").read_text()
    page = parse(tmp_path / "rep" / "run_1.html")
    assert page.trial_rows == 12 and len(page.images) == 1  # the trials still show, with their returns
    assert "Not shown" in text and "is not this run&#x27;s task &#x27;synthetic&#x27;" in text


PWN = """
import pathlib
pathlib.Path("PWNED").write_text("code named in the store ran")
def make():
    raise SystemExit("pwned")
"""


def test_report_never_imports_a_task_named_in_the_store(tmp_path, monkeypatch):
    """A store whose task_spec names `pwn:make`, with pwn.py in the working directory: nothing of it runs."""
    store = tmp_path / "run.corl"
    task = load_task("synthetic", seed=2)
    with RunStore(store) as db:
        StoredRun.start(db, task, task_spec="pwn:make", method="CORL+PIBU", seed=2).run(task, max_trials=12)
    (tmp_path / "pwn.py").write_text(PWN)
    monkeypatch.chdir(tmp_path)
    res = runner.invoke(app, ["report", "--store", str(store), "--out", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    assert not (tmp_path / "PWNED").exists()
    assert "no --task given" in res.stderr and "without J" in res.stderr  # says what the pages leave out
    text = (tmp_path / "rep" / "run_1.html").read_text()
    assert parse(tmp_path / "rep" / "run_1.html").trial_rows == 12
    assert "No task was named" in text and "pwn:make" in text  # shown as stored text, never imported
    # with the task named on the command line, the page is complete
    res = report(store, tmp_path / "full")
    assert res.exit_code == 0, res.output
    assert not (tmp_path / "PWNED").exists()
    assert len(parse(tmp_path / "full" / "run_1.html").images) > len(parse(tmp_path / "rep" / "run_1.html").images)
    assert "No task was named" not in (tmp_path / "full" / "run_1.html").read_text()
