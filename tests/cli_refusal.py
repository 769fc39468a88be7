"""What every hostile CLI test checks of a refusal: one line ``error: ...``, exit 2, no traceback."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from corl.cli import app

runner = CliRunner()


def listing(folder: Path) -> list[str]:
    """Every file and folder under ``folder`` (relative names, sorted), ``__pycache__`` left out."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if "__pycache__" not in p.parts)


def state(folder: Path) -> dict[str, tuple[bytes, int]]:
    """Every file under ``folder``: its bytes and modification time (ns)."""
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file() and "__pycache__" not in p.parts}


def copy_of(template: Path, tmp_path: Path, monkeypatch) -> Path:
    """A copy of ``template`` to work in: the current folder, importable (a task module there)."""
    import shutil

    folder = tmp_path / "case"
    shutil.copytree(template, folder)
    monkeypatch.chdir(folder)
    monkeypatch.syspath_prepend(str(folder))
    return folder


def refuse(args: list[str], message: str):
    """Run ``corl ARGS``; assert it was refused in one line holding ``message``. Returns (result, line)."""
    res = runner.invoke(app, args)
    assert res.exit_code == 2, (args, res.output)
    assert isinstance(res.exception, SystemExit), (args, res.exception)  # no traceback
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], (args, res.stderr)
    return res, lines[0]
