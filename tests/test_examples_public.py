"""The examples are what users copy: they import only corl's public names (issue 33).

Public: a name listed in the ``__all__`` of ``corl`` or of one of its top-level modules or packages
(``corl.mujoco``, ``corl.trajectory``, ``corl.problem``, ...), never a module below those
(``corl.mujoco.parse``) nor a name a module leaves out of its ``__all__``.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.py"))


def corl_imports(path: Path):
    """``(line, module, name)`` of every ``from corl... import name`` and ``import corl...`` in ``path``."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "corl":
            for alias in node.names:
                yield node.lineno, node.module, alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "corl":
                    yield node.lineno, alias.name, None


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.name for p in EXAMPLES])
def test_an_example_imports_public_names_only(path):
    private = []
    for line, module, name in corl_imports(path):
        if len(module.split(".")) > 2:
            private.append(f"{path.name}:{line} imports from {module}, below corl's public modules")
            continue
        public = getattr(importlib.import_module(module), "__all__", None)
        if name is not None and (public is None or name not in public):
            private.append(f"{path.name}:{line} imports {name} from {module}, which does not list it in __all__")
    assert not private, "\n".join(private)


def test_the_check_catches_a_private_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("from corl.mujoco.parse import parse_mjcf\nfrom corl.realise import _plain\n")
    found = list(corl_imports(bad))
    assert found == [(1, "corl.mujoco.parse", "parse_mjcf"), (2, "corl.realise", "_plain")]
    assert "_plain" not in importlib.import_module("corl.realise").__all__
