"""benchmarks/hostile_serve.py: hostile requests and command lines against ``corl serve`` (loopback only).
Every probe gets its status with a one-line JSON error (or a one-line ``error:`` and exit 2), no
traceback, and the run is unchanged and still works afterwards."""

from __future__ import annotations

import pytest
from benchmark_module import load_benchmark

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")


def test_every_hostile_probe_is_refused_as_it_should_be(tmp_path):
    hostile = load_benchmark("hostile_serve")
    results = hostile.run_all(tmp_path)
    print(hostile.table(results))
    assert len(results) >= 45
    for kind in ("401", "413", "400", "409"):  # what issue 24 names, each probed at least once
        assert any(r.expected == int(kind) and r.ok for r in results), kind
    assert [r.probe for r in results if not r.ok] == []
