"""Where a benchmark sweep runs: joblib on local processes, on a Ray cluster or on a Dask cluster.

Glossary
--------
backend : the name a sweep is given, one of :data:`BACKENDS`; it is also the joblib backend used
          inside :func:`cluster`
loky    : joblib's default, worker processes on this machine (nothing to start or stop)
ray     : joblib over Ray actors (``ray.util.joblib``); ``address`` joins a running cluster
          (``auto``, ``HOST:PORT`` or ``ray://HOST:10001``), otherwise a local Ray with ``jobs`` CPUs
dask    : joblib over ``distributed`` (joblib's ``dask`` backend); ``address`` joins a scheduler
          (``tcp://HOST:8786``), otherwise a local cluster of ``jobs`` single-threaded processes

A sweep opens :func:`cluster` once and hands every batch of calls to :func:`run_unordered`, which
yields ``(index, result)`` as calls finish. The sweeps file results by index or sort them by key,
so the numbers never depend on the order in which workers finish: every backend gives the table
loky gives for the same seeds (only wall times differ). A remote cluster's workers must have the
same versions of corl and its libraries installed.
"""

from __future__ import annotations

import logging
import math
import os
import socket
from contextlib import ExitStack, contextmanager
from importlib.util import find_spec
from typing import Any, Callable, Iterable, Iterator, Sequence

from corl.errors import InputError, MissingExtraError

__all__ = ["BACKENDS", "WORKER_ENV", "check_backend", "cluster", "run_unordered"]

BACKENDS = ("loky", "ray", "dask")
# backend -> (the module it imports, the extra that installs it)
_EXTRAS = {"ray": ("ray", "ray"), "dask": ("distributed", "dask")}
# One BLAS thread per worker: the small factorizations of a run are far slower with more.
WORKER_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
_PROGRESS_STEPS = 20  # without generator support, results come back in about this many chunks


def check_backend(backend: str, address: str | None = None) -> None:
    """Raise a clear error for an unknown backend, an address loky cannot use, or a missing extra."""
    if backend not in BACKENDS:
        raise InputError(f"unknown backend '{backend}'; choose one of {', '.join(BACKENDS)}")
    if address is not None and backend == "loky":
        raise InputError(f"an address ('{address}') needs --backend ray or dask; loky runs on this machine only")
    if backend in _EXTRAS:
        module, extra = _EXTRAS[backend]
        if find_spec(module) is None:
            raise MissingExtraError(f"backend '{backend}' needs the extra: pip install 'corl-skills[{extra}]'")


@contextmanager
def _environ_defaults(values: dict[str, str]) -> Iterator[None]:
    """Set the variables of ``values`` that are unset, and unset them again on exit."""
    added = [k for k in values if k not in os.environ]
    os.environ.update({k: values[k] for k in added})
    try:
        yield
    finally:
        for k in added:
            os.environ.pop(k, None)


def _check_reachable(address: str, what: str, hint: str) -> None:
    """Fail in seconds when a ``HOST:PORT`` (or ``tcp://HOST:PORT``) address refuses connections.

    Ray retries an unreachable address for many minutes and ignores SIGTERM meanwhile, Dask for
    30 s; other forms (``auto``, ``ray://``, ``tls://``) are left to them.
    """
    host, _, port = address.removeprefix("tcp://").rpartition(":")
    if "://" in host or not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=5).close()
    except OSError as exc:
        raise InputError(f"cannot reach the {what} at '{address}' ({exc}); {hint}") from exc


def _ray(stack: ExitStack, jobs: int, address: str | None) -> None:
    """Join or start Ray (shut down on exit if started here) and register its joblib backend.

    A local Ray listens on the loopback only (when Ray is first imported here: Ray reads the
    switch at import) and sends no usage statistics; both environment variables can override.
    """
    hint = "start it with `ray start --head` or leave out --address for a local Ray"
    environ = {"RAY_USAGE_STATS_ENABLED": "0"}
    if address is None:
        environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"  # node address 127.0.0.1 (not when joining)
    else:
        _check_reachable(address, "Ray cluster", hint)
    stack.enter_context(_environ_defaults(environ))
    import ray
    from ray.util.joblib import register_ray

    if not ray.is_initialized():
        options: dict[str, Any] = {"runtime_env": {"env_vars": dict(WORKER_ENV)}, "log_to_driver": False,
                                   "logging_level": logging.WARNING}
        if address is None:
            # "local": a Ray of our own even when another one runs on this machine (it would be joined)
            options.update(address="local", num_cpus=jobs, include_dashboard=False)
        else:
            options.update(address=address)
        try:
            ray.init(**options)
        except ConnectionError as exc:  # its cause says more (a missing auth token: RAY_AUTH_MODE=token)
            reason = f"{exc}: {exc.__cause__}" if exc.__cause__ is not None else str(exc)
            raise InputError(f"cannot reach the Ray cluster at '{address}' ({reason}); {hint}") from exc
        stack.callback(ray.shutdown)
    register_ray()
    # joblib hands the pool a 'context' argument Ray ignores; its warning says nothing useful here.
    pool_log = logging.getLogger("ray.util.multiprocessing.pool")
    stack.callback(pool_log.setLevel, pool_log.level)
    pool_log.setLevel(logging.ERROR)


def _dask(stack: ExitStack, jobs: int, address: str | None) -> None:
    """Join a scheduler or start a local cluster of processes; the client becomes the default."""
    from distributed import Client, LocalCluster, get_client

    hint = "start one with `dask scheduler` and `dask worker ADDRESS`, or leave out --address"
    if address is None:
        try:
            get_client()  # a client the caller opened already (or an outer cluster()): use it
            return
        except ValueError:
            pass
        local = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
                             dashboard_address=None, env=dict(WORKER_ENV), silence_logs=logging.ERROR)
        stack.callback(local.close)
        address = local.scheduler_address
    else:
        _check_reachable(address, "Dask scheduler", hint)
    try:
        client = Client(address, timeout="30s")
    except OSError as exc:
        raise InputError(f"cannot reach the Dask scheduler at '{address}' ({exc}); {hint}") from exc
    stack.callback(client.close)


@contextmanager
def cluster(backend: str, jobs: int = -1, address: str | None = None) -> Iterator[None]:
    """Make ``backend`` ready for joblib for the duration of the ``with`` block.

    Parameters
    ----------
    backend : one of :data:`BACKENDS`.
    jobs : workers of a local Ray or Dask cluster (joblib's convention: -1 all cores); unused
        with loky (its workers come with each call) and with an ``address``.
    address : a running Ray or Dask cluster to join instead of starting a local one.

    A Ray or Dask cluster already running in this process (an outer ``cluster`` block, or one the
    caller opened) is used as it is and left running; whatever this block starts it stops.
    Workers get :data:`WORKER_ENV` (Ray through its ``runtime_env``; a local Dask cluster through
    its nannies; the workers of a Dask scheduler at ``address`` keep their own environment).
    """
    from joblib import effective_n_jobs, parallel_config

    check_backend(backend, address)
    if backend == "loky":
        yield
        return
    workers = max(1, effective_n_jobs(jobs))  # a local cluster's size, counted as loky would
    with ExitStack() as stack:
        (_ray if backend == "ray" else _dask)(stack, workers, address)
        stack.enter_context(parallel_config(backend=backend))
        yield


def run_unordered(func: Callable, arguments: Sequence[tuple], *, jobs: int = -1, backend: str = "loky",
                  batch_size: int = 1) -> Iterator[tuple[int, Any]]:
    """``(k, func(*arguments[k]))`` for every k, in the order the calls finish.

    Uses joblib's ``return_as="generator_unordered"`` where the backend supports it (loky, dask).
    Ray's joblib backend does not, so there the calls go in about :data:`_PROGRESS_STEPS` chunks
    through one pool, and a chunk's results come together: progress is coarser, results the same.
    Call inside :func:`cluster` for ray and dask.
    """
    from joblib import Parallel, delayed, effective_n_jobs, parallel_config

    calls = [delayed(_tagged)(k, func, args) for k, args in enumerate(arguments)]
    # The backend comes from parallel_config, not Parallel(backend=...): joblib 1.5 hands a backend
    # named in Parallel a ``nesting_level`` that the dask backend passes on to every task.
    with parallel_config(backend=backend):
        try:
            parallel = Parallel(n_jobs=jobs, return_as="generator_unordered", batch_size=batch_size)
        except ValueError as exc:
            if "return_as" not in str(exc):
                raise
            parallel, workers = None, max(1, effective_n_jobs(jobs))
            pool = Parallel(n_jobs=jobs, batch_size=batch_size)
    if parallel is not None:
        yield from parallel(calls)
        return
    size = max(2 * workers * batch_size, math.ceil(len(calls) / _PROGRESS_STEPS))
    with pool:  # one pool for all chunks
        for start in range(0, len(calls), size):
            yield from pool(calls[start:start + size])


def _tagged(k: int, func: Callable, args: Iterable) -> tuple[int, Any]:
    return k, func(*args)
