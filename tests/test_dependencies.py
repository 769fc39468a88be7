"""pyproject.toml declares ranges; constraints-lowest.txt holds their lower bounds (make test-lowest)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from packaging.requirements import Requirement

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

ROOT = Path(__file__).resolve().parents[1]


def _pins(path: Path) -> dict[str, str]:
    pins = {}
    for line in path.read_text().splitlines():
        line = line.split("#")[0].strip()
        if line:
            name, _, version = line.partition("==")
            pins[re.sub(r"[-_.]+", "-", name).lower()] = version
    return pins


def _requirements():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    return [Requirement(r) for r in project["dependencies"] + project["optional-dependencies"]["test"]]


def test_no_dependency_is_pinned_exactly_and_each_has_a_lower_bound():
    for req in _requirements():
        ops = {s.operator for s in req.specifier}
        assert "==" not in ops, f"{req}: pin exact versions in constraints.txt, declare a range in pyproject.toml"
        assert ">=" in ops, f"{req}: declare the lowest version corl works with"


def test_constraints_lowest_are_the_declared_lower_bounds():
    lowest = _pins(ROOT / "constraints-lowest.txt")
    for req in _requirements():
        bound = next(s.version for s in req.specifier if s.operator == ">=")
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        assert name in lowest, f"{req.name} is missing from constraints-lowest.txt"
        assert lowest[name].split(".")[:len(bound.split("."))] == bound.split("."), \
            f"{req.name}: constraints-lowest.txt has {lowest[name]}, pyproject.toml's lower bound is {bound}"


def test_constraints_pin_every_dependency_inside_its_range():
    pins = _pins(ROOT / "constraints.txt")
    for req in _requirements():
        name = re.sub(r"[-_.]+", "-", req.name).lower()
        assert name in pins, f"{req.name} is missing from constraints.txt"
        assert req.specifier.contains(pins[name]), f"constraints.txt pins {req.name}=={pins[name]} outside {req.specifier}"
