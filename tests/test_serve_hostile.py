"""benchmarks/hostile_serve.py: hostile requests and command lines against ``corl serve`` (loopback only).
Every probe gets its status with a one-line JSON error (or a one-line ``error:`` and exit 2), no
traceback, and the run is unchanged and still works afterwards. Under floods and slow clients (the load
probes), a well-behaved client is still served within 5 s."""

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


@pytest.mark.slow
def test_floods_and_slow_clients_leave_a_well_behaved_client_served(tmp_path):
    """The server with a file limit of 1,024 (ulimit -n): 1,100 idle half-sent requests ('GET /sta'), slow
    headers, slow bodies with and without the token. A well-behaved GET /status is answered within 5 s
    throughout, every hostile connection is closed by the server, stderr stays under 1 MB, and the run is
    as it was."""
    hostile = load_benchmark("hostile_serve")
    results = hostile.run_load(tmp_path)
    print(hostile.load_table(results))
    flood = results[0]
    assert flood.opened == hostile.FLOOD == 1100 and hostile.SERVER_FILES == 1024
    assert flood.answered == flood.asked > 10 and flood.worst_ms < 5000 and flood.stderr_bytes < 1_000_000
    assert sum(r.stderr_bytes for r in results) < 1_000_000
    assert [r.probe for r in results if not r.ok] == []
