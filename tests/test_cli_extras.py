"""A command whose optional dependency is missing names the extra to install, in one line, exit 2."""

from __future__ import annotations

import sys

import pytest


@pytest.mark.parametrize("module, extra", [("uvicorn", "serve"), ("ray", "ray"), ("pyarrow", "parquet")])
def test_a_missing_optional_dependency_names_its_extra(monkeypatch, capsys, module, extra):
    import corl.cli as cli

    def needs_it():
        raise ModuleNotFoundError(f"No module named '{module}'", name=module)

    monkeypatch.setattr(cli, "app", needs_it)
    monkeypatch.delenv("CORL_DEBUG", raising=False)
    with pytest.raises(SystemExit) as info:
        cli.main()
    err = capsys.readouterr().err
    assert info.value.code == 2 and len(err.strip().splitlines()) == 1
    assert f"'{extra}' extra" in err and f"pip install 'corl-skills[{extra}]'" in err  # PyPI's corl is another project
    assert "internal error" not in err and "bug" not in err


def test_a_missing_module_that_is_no_extra_is_still_an_internal_error(monkeypatch, capsys):
    import corl.cli as cli

    def broken():
        raise ModuleNotFoundError("No module named 'nosuchthing'", name="nosuchthing")

    monkeypatch.setattr(cli, "app", broken)
    monkeypatch.delenv("CORL_DEBUG", raising=False)
    with pytest.raises(SystemExit) as info:
        cli.main()
    assert info.value.code == 1 and "internal error" in capsys.readouterr().err
    assert sys.modules.get("nosuchthing") is None
