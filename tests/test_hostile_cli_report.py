"""Result files on a full disk (corl/store/files.py, corl/experiments/html/report.py, corl/cli/common.py):
`corl report` and `corl run` stop with one line, exit 2, and leave neither a half-written page nor the
temporary file it was written through."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError
from corl.store.files import write_atomically, write_text_atomically

runner = CliRunner()


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts)


def full_disk_after(nbytes: int, names: tuple[str, ...]):
    """``Path.write_text`` that writes ``nbytes`` of files whose name contains one of ``names``, then
    raises ENOSPC, as a disk that fills up midway."""
    real = Path.write_text

    def write_text(self, data, *args, **kwargs):
        if not any(n in self.name for n in names):
            return real(self, data, *args, **kwargs)
        real(self, data[:nbytes], *args, **kwargs)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    return write_text


@pytest.fixture
def store(tmp_path):
    res = runner.invoke(app, ["ask", "--store", str(tmp_path / "s.corl"), "--task", "synthetic", "--raw",
                              "--out", str(tmp_path / "trials")])
    assert res.exit_code == 0, res.output
    return tmp_path / "s.corl"


def test_report_to_a_full_disk_leaves_no_temporary_page(store, tmp_path, monkeypatch):
    monkeypatch.setattr(Path, "write_text", full_disk_after(100, ("run_1.html",)))
    before = listing(tmp_path)
    res = runner.invoke(app, ["report", "--store", str(store), "--out", str(tmp_path / "rep"), "--no-video", "-q"])
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit), res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: cannot write") and "run_1.html" in lines[0], res.stderr
    assert "No space left on device" in lines[0]
    assert listing(tmp_path) == before  # no run_1.html, no run_1.html.tmp, no empty rep/


def test_report_figures_on_a_full_disk(store, tmp_path, monkeypatch):
    """The figures are drawn in a temporary folder first: a full disk there is one line too."""
    import corl.experiments.figures as figures

    res = runner.invoke(app, ["tell", "--store", str(store), "--task", "synthetic", "--success", "yes",
                              "--return", "0.2"])
    assert res.exit_code == 0, res.output

    def full(plt, fig, path, **kwargs):  # kwargs: the trial it was drawn at
        Path(path).write_bytes(b"\x89PNG half")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(figures, "_save", full)
    before = listing(tmp_path)
    res = runner.invoke(app, ["report", "--store", str(store), "--out", str(tmp_path / "rep"), "--no-video", "-q",
                              "--task", "synthetic"])
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit), res.output
    assert res.stderr.startswith("error: cannot draw the figures of run 1") and "No space left" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1 and listing(tmp_path) == before


def test_a_page_written_before_survives_a_full_disk(store, tmp_path, monkeypatch):
    rep = tmp_path / "rep"
    res = runner.invoke(app, ["report", "--store", str(store), "--out", str(rep), "--no-video", "-q"])
    assert res.exit_code == 0, res.output
    page = (rep / "run_1.html").read_text()
    monkeypatch.setattr(Path, "write_text", full_disk_after(100, ("run_1.html",)))
    res = runner.invoke(app, ["report", "--store", str(store), "--out", str(rep), "--no-video", "-q"])
    assert res.exit_code == 2, res.output
    assert listing(rep) == ["run_1.html"] and (rep / "run_1.html").read_text() == page


def test_summary_json_of_corl_run_on_a_full_disk(tmp_path, monkeypatch):
    monkeypatch.setattr(Path, "write_text", full_disk_after(10, ("summary.json",)))
    out = tmp_path / "o"
    res = runner.invoke(app, ["run", "synthetic", "--out", str(out), "--no-video", "-q"])
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit), res.output
    assert res.stderr.startswith("error: cannot write") and "summary.json" in res.stderr, res.stderr
    assert not any("summary" in name for name in listing(out))


@pytest.mark.parametrize("error", [OSError(errno.ENOSPC, "No space left on device"), KeyboardInterrupt()])
def test_write_atomically_removes_its_temporary_file(tmp_path, error):
    target = tmp_path / "a.json"
    target.write_text("old")

    def half(tmp: Path) -> None:
        tmp.write_bytes(b"half")
        raise error

    with pytest.raises(InputError if isinstance(error, OSError) else KeyboardInterrupt):
        write_atomically(target, half)
    assert listing(tmp_path) == ["a.json"] and target.read_text() == "old"
    assert write_text_atomically(target, json.dumps({"new": 1})) == target
    assert json.loads(target.read_text()) == {"new": 1} and listing(tmp_path) == ["a.json"]
    assert oct(target.stat().st_mode & 0o777) == oct(0o644)
