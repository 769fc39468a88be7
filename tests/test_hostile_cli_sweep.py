"""`corl sweep` under hostile input (corl/cli/bench.py, corl/experiments/sweep.py, corl/store/files.py):
the central argument checks, a grid too large to hold, an unwritable or full place, a task whose
rollout raises or exits. Each is one line ``error: ...``, exit 2, and leaves nothing behind."""

from __future__ import annotations

import errno
import os
import resource
import subprocess
import sys
from pathlib import Path

import pytest
from cli_refusal import listing, refuse
from typer.testing import CliRunner

import corl.experiments.sweep as sweep_module
from corl.cli import app
from corl.errors import InputError
from corl.experiments.sweep import MAX_SWEEP_POINTS, parse_grid

runner = CliRunner()

# A task whose rollout raises, and one whose rollout calls sys.exit (user code that must not end corl).
USERTASK = """
import sys
from corl.tasks.synthetic import SyntheticTask

class Burning(SyntheticTask):
    name = "burning"
    def rollout(self, w):
        raise RuntimeError("the robot is on fire")

class Leaving(SyntheticTask):
    name = "leaving"
    def rollout(self, w):
        sys.exit(0)

def burning():
    return Burning((0.6, 0.4))

def leaving():
    return Leaving((0.6, 0.4))
"""


@pytest.fixture
def workdir(tmp_path, monkeypatch):
    (tmp_path / "sweeptask.py").write_text(USERTASK)
    (tmp_path / "afile.txt").write_text("a file, not a folder\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    sys.modules.pop("sweeptask", None)


def refused(args: list[str], folder: Path, message: str):
    before = listing(folder)
    _, line = refuse(args, message)
    assert listing(folder) == before, args  # no sweep.csv, no temporary file, no empty folder
    return line


@pytest.mark.parametrize("args, message", [
    (["--jobs", "0"], "--jobs must be"),
    (["--jobs", "-3"], "--jobs must be"),
    (["--seed", "-1"], "--seed must be"),
    (["--out", "afile.txt"], "is a file"),
    (["--out", "afile.txt/sub"], "cannot be created"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_sweep_arguments_go_through_the_central_checks(workdir, args, message):
    refused(["sweep", "synthetic", "--grid", "5", "-q", *(args if "--out" in args else [*args, "--out", "sw"])],
            workdir, message)


def test_sweep_task_spec_is_checked(workdir):
    refused(["sweep", "..:x", "--grid", "5", "--out", "sw", "-q"], workdir, "is not an import path")


def test_sweep_to_a_place_where_nothing_can_be_created(workdir, monkeypatch):
    """Read-only media: mkdir fails even for root (EROFS); refused before any rollout."""
    real_mkdir = Path.mkdir

    def read_only(self, *args, **kwargs):
        if self.name == "ro":
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", read_only)
    monkeypatch.setattr(sweep_module, "sweep_task", lambda *a, **k: pytest.fail("swept before the check"))
    refused(["sweep", "synthetic", "--grid", "5", "--out", "ro", "-q"], workdir, "Read-only file system")


def test_sweep_into_an_existing_unwritable_folder(workdir, monkeypatch):
    (workdir / "locked").mkdir()
    real_access = os.access
    monkeypatch.setattr(os, "access",
                        lambda p, mode: not (mode & os.W_OK and Path(p).name == "locked") and real_access(p, mode))
    refused(["sweep", "synthetic", "--grid", "5", "--out", "locked", "-q"], workdir, "not a writable folder")


def test_a_full_disk_leaves_no_partial_sweep_csv(workdir, monkeypatch):
    """The CSV is written through a temporary file: half of it written, then ENOSPC, leaves nothing."""
    real_open = open

    def full_disk(path, mode="r", *args, **kwargs):
        f = real_open(path, mode, *args, **kwargs)
        if "w" in mode:
            f.write("theta1,realised,success,return\n0.1,1,")  # part of the file reached the disk
            f.close()
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return f

    monkeypatch.setattr(sweep_module, "open", full_disk, raising=False)
    line = refused(["sweep", "synthetic", "--grid", "5", "--out", "sw", "-q"], workdir, "No space left on device")
    assert "sweep.csv" in line
    assert not (workdir / "sw").exists()  # created by the command, removed again while empty


def test_an_existing_sweep_csv_survives_a_full_disk(workdir, monkeypatch):
    (workdir / "sw").mkdir()
    (workdir / "sw" / "sweep.csv").write_text("the previous sweep\n")

    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(sweep_module, "_write_csv", full_disk)
    refused(["sweep", "synthetic", "--grid", "5", "--out", "sw", "-q"], workdir, "No space left on device")
    assert (workdir / "sw" / "sweep.csv").read_text() == "the previous sweep\n"


@pytest.mark.parametrize("spec, raised", [("sweeptask:burning", "RuntimeError: the robot is on fire"),
                                          ("sweeptask:leaving", "SystemExit: 0")])
def test_a_rollout_that_raises_is_reported_naming_the_task(workdir, spec, raised):
    line = refused(["sweep", spec, "--grid", "5", "--out", "sw", "-q"], workdir, raised)
    assert f"the rollout of task '{spec.split(':')[1]}'" in line and "theta" in line


def test_grid_too_large_is_refused_before_any_array():
    with pytest.raises(InputError, match=f"at most {MAX_SWEEP_POINTS}"):
        parse_grid("1000000000", 1)
    with pytest.raises(InputError, match="1002001 grid points"):
        parse_grid("1001,1001", 2)
    assert parse_grid("1000,1000", 2) == (1000, 1000)  # exactly MAX_SWEEP_POINTS
    with pytest.raises(InputError, match="--grid"):
        parse_grid("9" * 5000, 1)  # more digits than int() reads


def test_grid_too_large_from_the_command_line(tmp_path):
    """In a subprocess whose address space is capped, so that a regression is a MemoryError, not an OOM kill."""

    def cap_memory():
        resource.setrlimit(resource.RLIMIT_AS, (4 * 2**30, 4 * 2**30))

    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    env.pop("CORL_DEBUG", None)
    res = subprocess.run([sys.executable, "-m", "corl.cli", "sweep", "synthetic", "--grid", "1000000000",
                          "--out", str(tmp_path / "sw"), "-q"], capture_output=True, text=True, env=env,
                         preexec_fn=cap_memory, timeout=120)
    assert res.returncode == 2, res.stderr
    assert res.stderr.startswith("error: --grid '1000000000' makes 1000000000 grid points") and \
        len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_help_names_the_largest_grid():
    res = runner.invoke(app, ["sweep", "--help"], env={"COLUMNS": "300"})
    assert str(MAX_SWEEP_POINTS) in res.output
