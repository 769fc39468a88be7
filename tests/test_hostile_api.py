"""benchmarks/hostile_api.py: every bad call to the public API is refused in one line, every huge
but finite return works; no raw exception (issue 21)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import hostile_api  # noqa: E402


def test_every_api_case_is_refused_in_one_line_or_works(capsys):
    assert hostile_api.main() == 0
    out = capsys.readouterr().out
    assert "0 raw exceptions, 0 problems" in out.splitlines()[-1]
    assert "kit loaders" in out  # mujoco is a dependency: the kit's cases ran
