"""The API reference (``make docs``): every module imports, and pdoc renders the NumPy docstrings."""

from __future__ import annotations

import importlib
import importlib.util
import pkgutil
from pathlib import Path

import pytest

import corl

BUILD_API = Path(__file__).resolve().parents[1] / "docs" / "build_api.py"


def _build_api():
    spec = importlib.util.spec_from_file_location("build_api", BUILD_API)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_module_imports_and_has_a_docstring():
    names = [m.name for m in pkgutil.walk_packages(corl.__path__, "corl.")]
    assert len(names) > 50 and "corl.store.sqlite" in names and "corl.tasks.door.sim" in names
    undocumented = [n for n in ["corl", *names] if not (importlib.import_module(n).__doc__ or "").strip()]
    assert undocumented == []


def test_pdoc_writes_a_page_per_module_with_the_docstrings(tmp_path):
    pytest.importorskip("pdoc")
    from pdoc.extract import walk_specs

    build_api = _build_api()
    assert sorted(walk_specs(build_api.specs())) == sorted(build_api.module_names())  # no module left out
    pages = build_api.build(tmp_path, ["corl.problem", "corl.progress"])
    assert {p.relative_to(tmp_path).as_posix() for p in pages} >= {"corl/problem.html", "corl/progress.html"}
    problem = (tmp_path / "corl" / "problem.html").read_text()
    assert "The structured problem of Eq. 2-5" in problem and 'id="Proposal"' in problem
    progress = (tmp_path / "corl" / "progress.html").read_text()
    assert "<h6 id=\"parameters\">Parameters</h6>" in progress and 'id="Tracker.update"' in progress
