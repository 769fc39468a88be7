"""``corl serve``: the learner in one long-lived process beside the robot, reachable over HTTP.

A robot stack (a ROS node, a lab's control PC, a notebook on another machine) asks for a trial,
runs it and tells its outcome; the learner stays in memory, so no request replays the run, and
every trial is committed to the run store before it is answered (:mod:`corl.serve.run`). The
HTTP API and its rules are in :mod:`corl.serve.app` and :mod:`corl.serve.guard`, the deadlines and
caps that keep it serving under floods and slow clients in :mod:`corl.serve.limits` and
:mod:`corl.serve.connections`; the client is :class:`corl.client.Client`. Needs the ``serve``
extra: ``pip install 'corl-skills[serve]'``.

From Python, :func:`background` runs a server in a thread (a notebook, a test)::

    with background("run.corl", "synthetic") as url:
        client = Client(url)
        ...
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time
from pathlib import Path
from typing import Callable

from corl.errors import InputError, MissingExtraError
from corl.serve.guard import check_bind, is_loopback, read_token
from corl.serve.limits import ACCEPT_BATCH, OncePerInterval, ServeLimits

__all__ = ["serve_forever", "background", "check_bind", "read_token", "is_loopback", "ServeLimits"]


def _require() -> None:
    try:
        import starlette  # noqa: F401
        import uvicorn  # noqa: F401
    except ImportError as exc:
        raise MissingExtraError(f"corl serve needs {exc.name}: pip install 'corl-skills[serve]' (Starlette and uvicorn)") \
            from None


def _listen(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port``: a port in use fails here, with OSError, before the run is opened."""
    family = socket.AF_INET6 if ":" in host.strip("[]") else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        # Accepted connections inherit TCP_NODELAY (Linux): without it, a keep-alive client waits out
        # Nagle's algorithm against its delayed ACK, 40 ms on every request after the first.
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        sock.bind((host.strip("[]"), port))
        sock.listen(ACCEPT_BATCH)
    except OSError:
        sock.close()
        raise
    return sock


def _url(sock: socket.socket, host: str) -> str:
    port = sock.getsockname()[1]
    host = host.strip("[]")
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


def _server(store, task: str, *, method, seed, host: str, port: int, token, rate: float, video: bool,
            access_log: bool, limits: ServeLimits | None, robots: int | None = None):
    """``(uvicorn.Server, socket, ServedRun, url)``: listening, the run replayed, nothing served yet."""
    _require()
    import uvicorn

    from corl.serve.app import create_app
    from corl.serve.connections import Tracker, protocol_class
    from corl.serve.dashboard import Figures, Video
    from corl.serve.run import ServedRun

    if limits is not None and not isinstance(limits, ServeLimits):
        raise InputError(f"limits must be a corl.serve.ServeLimits, got {limits!r:.80}")
    tracker = Tracker(limits or ServeLimits())
    check_bind(host, token)
    sock = _listen(host, port)
    try:
        run = ServedRun(Path(store), task, method=method, seed=seed, rate=rate, robots=robots)
    except BaseException:
        sock.close()
        raise
    renders = video and callable(getattr(run.task, "render_comparison", None))
    app = create_app(run, token=token, loopback=is_loopback(host), figures=Figures(),
                     video=Video(task, int(run.info.seed or 0)) if renders else None)
    # http: uvicorn's h11 protocol with read deadlines and caps (corl.serve.connections); ws: no upgrades,
    # which would hand a connection to a protocol that counts nothing; backlog: the most accepted per loop turn
    config = uvicorn.Config(app, log_level="warning", access_log=access_log, lifespan="on",
                            timeout_graceful_shutdown=2, http=protocol_class(tracker), ws="none",
                            backlog=ACCEPT_BATCH, timeout_keep_alive=5)
    OncePerInterval.attach(tracker.limits.log_interval)

    class Server(uvicorn.Server):
        async def startup(self, sockets=None) -> None:  # accept() out of files: one line per interval, not a traceback
            asyncio.get_running_loop().set_exception_handler(tracker.on_loop_error)
            await super().startup(sockets=sockets)

        def handle_exit(self, sig, frame) -> None:  # SIGINT, SIGTERM: end the dashboards' event streams too
            app.state.notifier.close()
            super().handle_exit(sig, frame)

    return Server(config), sock, run, _url(sock, host)


def serve_forever(store, task: str, *, method: str | None = None, seed: int | None = None, host: str = "127.0.0.1",
                  port: int = 8765, token: str | None = None, rate: float = 100.0, video: bool = True,
                  access_log: bool = False, ready: Callable[[str, dict], None] | None = None,
                  limits: ServeLimits | None = None, robots: int | None = None) -> None:
    """Serve the store's latest run (or a new one) of ``task`` until SIGINT/SIGTERM; ``ready(url, status)``
    is called once the socket listens; ``limits``: deadlines and caps (default ``ServeLimits()``);
    ``robots``: K of a new run, up to K trials out, one per robot (:mod:`corl.serve.fleet`; None: 1, or the
    stored run's). Raises CorlError (a refused run or bind) or OSError (the port)."""
    server, sock, run, url = _server(store, task, method=method, seed=seed, host=host, port=port, token=token,
                                     rate=rate, video=video, access_log=access_log, limits=limits, robots=robots)
    try:
        if ready is not None:
            ready(url, run.status)
        server.run(sockets=[sock])
    finally:
        run.close()
        sock.close()


@contextlib.contextmanager
def background(store, task: str, *, method: str | None = None, seed: int | None = None, port: int = 0,
               token: str | None = None, rate: float = 100.0, video: bool = False, timeout: float = 60.0,
               limits: ServeLimits | None = None, robots: int | None = None):
    """A server on 127.0.0.1 in a thread of this process; yields its URL and stops it on exit."""
    server, sock, run, url = _server(store, task, method=method, seed=seed, host="127.0.0.1", port=port,
                                     token=token, rate=rate, video=video, access_log=False, limits=limits,
                                     robots=robots)
    thread = threading.Thread(target=server.run, kwargs={"sockets": [sock]}, name="corl-serve", daemon=True)
    try:
        thread.start()
        deadline = time.monotonic() + timeout
        while not server.started:
            if not thread.is_alive() or time.monotonic() > deadline:
                raise RuntimeError(f"the server on {url} did not start within {timeout} s")
            time.sleep(0.01)
        yield url
    finally:
        server.handle_exit(None, None)
        thread.join(timeout)
        run.close()
        sock.close()
