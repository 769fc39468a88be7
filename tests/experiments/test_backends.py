"""Where sweeps run (corl.experiments.backends): loky, a local Ray, a local Dask cluster, the same table."""

from __future__ import annotations

import dataclasses
import sys
from importlib.util import find_spec

import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError, MissingExtraError
from corl.experiments.backends import BACKENDS, check_backend, cluster, run_unordered
from corl.experiments.synthetic import aggregate, sweep

_EXTRA_MODULES = {"ray": "ray", "dask": "distributed"}
METHODS = ["CORL+CMA", "PoWER"]  # one CORL method (motion optimization, GP) and one fast direct search


def _square(x: int) -> int:
    return x * x


def test_unknown_backend_is_a_clear_error_that_lists_the_choices():
    with pytest.raises(InputError, match="unknown backend 'spark'; choose one of loky, ray, dask"):
        check_backend("spark")
    with pytest.raises(InputError, match="unknown backend"):
        sweep(METHODS, 1, 0, backend="spark")
    res = CliRunner().invoke(app, ["bench", "synthetic", "--starts", "1", "--backend", "spark", "--quiet"])
    assert res.exit_code == 2 and "choose one of loky, ray, dask" in res.output


def test_an_address_needs_a_cluster_backend(tmp_path):
    with pytest.raises(InputError, match="needs --backend ray or dask"):
        check_backend("loky", "tcp://127.0.0.1:8786")
    res = CliRunner().invoke(app, ["bench", "door", "--address", "auto", "--out", str(tmp_path), "--quiet"])
    assert res.exit_code == 2 and "needs --backend ray or dask" in res.output


@pytest.mark.parametrize("backend", ["ray", "dask"])
def test_a_missing_package_names_the_extra_to_install(monkeypatch, backend):
    monkeypatch.setitem(sys.modules, _EXTRA_MODULES[backend], None)  # as if not installed: import fails
    message = rf"backend '{backend}' needs the extra: pip install 'corl-skills\[{backend}\]'"
    with pytest.raises(MissingExtraError, match=message):
        with cluster(backend, 1):
            pass
    res = CliRunner().invoke(app, ["bench", "synthetic", "--starts", "1", "--backend", backend, "--quiet"])
    assert res.exit_code == 2 and f"pip install 'corl-skills[{backend}]'" in res.output


@pytest.mark.parametrize("backend, address, what", [("ray", "127.0.0.1:1", "Ray cluster"),
                                                   ("dask", "tcp://127.0.0.1:1", "Dask scheduler")])
def test_an_unreachable_cluster_fails_at_once_with_a_hint(backend, address, what):
    if find_spec(_EXTRA_MODULES[backend]) is None:
        pytest.skip(f"needs the extra: pip install 'corl-skills[{backend}]'")
    with pytest.raises(InputError, match=f"cannot reach the {what} at '{address}'.*leave out --address"):
        with cluster(backend, 1, address):  # port 1 on the loopback refuses at once
            pass


def test_run_unordered_tags_each_result_with_its_call_also_in_chunks():
    arguments = [(k,) for k in range(7)]
    assert sorted(run_unordered(_square, arguments, jobs=1)) == [(k, k * k) for k in range(7)]
    # joblib's multiprocessing backend, like Ray's, cannot return a generator: the chunked path
    chunked = list(run_unordered(_square, arguments, jobs=2, backend="multiprocessing"))
    assert sorted(chunked) == [(k, k * k) for k in range(7)]


def _numbers(results) -> list:
    """Every field of every run but its wall time."""
    return [dataclasses.replace(r, seconds=0.0) for r in results]


def _table(results) -> dict:
    table = aggregate(results, METHODS)
    for row in table.values():
        row.pop("seconds")
    return table


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:`apply_async` is deprecated:DeprecationWarning")  # Ray's joblib backend
@pytest.mark.skipif(find_spec("ray") is None or find_spec("distributed") is None,
                    reason="needs the extras: pip install 'corl-skills[ray,dask]'")
def test_ray_and_dask_clusters_give_the_loky_table():
    assert BACKENDS == ("loky", "ray", "dask")
    reference = sweep(METHODS, 3, seed=0, jobs=2, backend="loky")
    assert len(reference) == 6 and sum(r.failures for r in reference) > 0

    seen = []
    with cluster("ray", 2):  # the sweep below joins this Ray and leaves it running
        import ray

        # loopback only (holds when cluster() is the first to import ray: Ray reads the switch at import)
        assert {n["NodeManagerAddress"] for n in ray.nodes()} == {"127.0.0.1"}
        on_ray = sweep(METHODS, 3, seed=0, jobs=2, backend="ray", progress=seen.append)
        assert ray.is_initialized()
    assert not ray.is_initialized()
    assert len(seen) == 6

    seen.clear()
    with cluster("dask", 2):
        from distributed import get_client

        assert get_client().scheduler.address.startswith("tcp://127.0.0.1:")
        on_dask = sweep(METHODS, 3, seed=0, jobs=2, backend="dask", progress=seen.append)
    with pytest.raises(ValueError):
        get_client()  # the local cluster and its client are gone
    assert len(seen) == 6

    assert _numbers(on_ray) == _numbers(reference)
    assert _numbers(on_dask) == _numbers(reference)
    assert _table(on_ray) == _table(reference) == _table(on_dask)
