"""benchmarks/hostile_api.py: every bad call to the public API is refused in one line, every huge
but finite return works; no raw exception (issue 21)."""

from benchmark_module import load_benchmark

hostile_api = load_benchmark("hostile_api")


def test_every_api_case_is_refused_in_one_line_or_works(capsys):
    assert hostile_api.main() == 0
    out = capsys.readouterr().out
    assert "0 raw exceptions, 0 problems" in out.splitlines()[-1]
    assert "kit loaders" in out  # mujoco is a dependency: the kit's cases ran
