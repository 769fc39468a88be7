"""benchmarks/hostile.py's fast subset: bad input to every subcommand, typed as a user would
(subprocess): a one-line error and exit 2, no traceback, every store unchanged (bytes and modification
time), nothing left behind."""

from __future__ import annotations

from benchmark_module import load_benchmark


def _hostile():
    return load_benchmark("hostile")


def test_fast_subset_of_hostile_inputs():
    hostile = _hostile()
    selected = [c for c in hostile.cases() if (c.command, c.label) in hostile.FAST]
    assert len(selected) == len(hostile.FAST)  # every named case exists
    assert {c.command.split()[0] for c in selected} >= {"run", "ask", "tell", "status", "runs", "export",
                                                       "report", "bench"}
    results = hostile.run_all(selected)
    print(hostile.table(results))
    for r in results:
        what = (r.case.command, r.case.label, r.code, r.first_line)
        assert not r.traceback, what
        assert r.code == 2 and r.first_line.startswith("error: "), what
        assert r.unchanged and r.left == [], (what, r.left)
