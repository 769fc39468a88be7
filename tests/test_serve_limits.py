"""Deadlines and caps of ``corl serve`` (:mod:`corl.serve.limits`, :mod:`corl.serve.connections`), against a
server in a thread with short deadlines and small caps: a request that does not arrive in time is
closed, trickling does not extend its deadline, an idle or slow client gives way to a new one past a
cap, an unauthenticated body is never read, and floods write a line per interval, not per event.
The flood at full size (1,100 connections against a file limit of 1,024) is in test_serve_hostile.py."""

from __future__ import annotations

import errno
import http.client
import json
import socket
import threading
import time

import pytest

pytest.importorskip("starlette")
pytest.importorskip("uvicorn")

from corl.client import Client, ServerError  # noqa: E402
from corl.errors import InputError  # noqa: E402
from corl.serve import ServeLimits, background  # noqa: E402
from corl.serve.connections import Tracker  # noqa: E402

TOKEN = "a-token-of-at-least-16-characters"


def _address(url: str) -> tuple[str, int]:
    host, port = url.rsplit("//", 1)[1].rsplit(":", 1)
    return host, int(port)


def _until_closed(sock: socket.socket, within: float) -> tuple[float, bytes]:
    """Seconds until the server closes ``sock`` (inf: still open after ``within``), and what it sent."""
    sock.settimeout(0.05)
    t0, got = time.monotonic(), b""
    while time.monotonic() - t0 < within:
        try:
            chunk = sock.recv(65536)
        except socket.timeout:
            continue
        except ConnectionError:
            return time.monotonic() - t0, got
        if not chunk:
            return time.monotonic() - t0, got
        got += chunk
    return float("inf"), got


def _opened(url: str, count: int, first: bytes) -> list[socket.socket]:
    """``count`` connections to the server at ``url`` that each sent ``first`` (an unfinished request)."""
    conns = []
    for _ in range(count):
        conns.append(socket.create_connection(_address(url)))
        conns[-1].sendall(first)
    time.sleep(0.2)  # the server has taken them in
    return conns


def _status(url: str, headers: dict | None = None) -> tuple[int, dict, dict]:
    conn = http.client.HTTPConnection(*_address(url), timeout=5)
    try:
        conn.request("GET", "/status", headers=headers or {})
        r = conn.getresponse()
        return r.status, dict(r.getheaders()), json.loads(r.read())
    finally:
        conn.close()


def test_a_half_sent_request_line_is_answered_408_and_closed_after_the_header_timeout(tmp_path):
    with background(tmp_path / "s.corl", "synthetic", limits=ServeLimits(header_timeout=0.5)) as url:
        with socket.create_connection(_address(url)) as s:
            s.sendall(b"GET /sta")
            took, got = _until_closed(s, 5.0)
        assert 0.4 < took < 2.0, took
        assert got.startswith(b"HTTP/1.1 408 ") and b'{"error": "the request\'s headers did not arrive within 0.5 s"}' \
            in got
        with socket.create_connection(_address(url)) as s:  # never a byte: closed as well, without a word
            took, got = _until_closed(s, 5.0)
        assert 0.4 < took < 2.0 and got == b""


@pytest.mark.parametrize("raw", [b"GARBAGE\r\n\r\n", b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\nno colon\r\n\r\n",
                                 b"\x00\x01\x02\r\n\r\n"])
def test_bytes_that_are_no_http_request_get_a_json_400_and_a_close(tmp_path, raw):
    with background(tmp_path / "s.corl", "synthetic") as url:
        with socket.create_connection(_address(url)) as s:
            s.sendall(raw)
            took, got = _until_closed(s, 5.0)
        assert took < 2.0
        head, _, body = got.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 400 ") and b"content-type: application/json" in head.lower()
        assert json.loads(body) == {"error": "Invalid HTTP request received: not a well-formed HTTP/1.1 request"}
        assert _status(url)[0] == 200  # and the server goes on


def test_trickling_headers_a_line_at_a_time_does_not_extend_the_deadline(tmp_path):
    with background(tmp_path / "s.corl", "synthetic", limits=ServeLimits(header_timeout=1.0)) as url:
        with socket.create_connection(_address(url)) as s:
            s.sendall(b"GET /status HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            t0 = time.monotonic()
            closed = None
            while time.monotonic() - t0 < 5.0 and closed is None:
                try:
                    s.sendall(b"X-Slow: 1\r\n")
                except OSError:
                    closed = time.monotonic() - t0
                    break
                took, _ = _until_closed(s, 0.2)
                if took != float("inf"):
                    closed = time.monotonic() - t0
        assert closed is not None and closed < 2.0, closed


def test_a_slow_body_is_closed_after_the_body_timeout_and_logs_no_internal_error(tmp_path, capfd):
    limits = ServeLimits(header_timeout=5.0, body_timeout=0.5)
    with background(tmp_path / "s.corl", "synthetic", limits=limits) as url:
        with socket.create_connection(_address(url)) as s:
            s.sendall(b"POST /ask HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                      b"Content-Length: 100\r\n\r\n{\"raw\": ")
            took, got = _until_closed(s, 5.0)
        assert 0.4 < took < 2.0, took
        assert got.startswith(b"HTTP/1.1 408 ") and b"body did not arrive within 0.5 s" in got
        assert _status(url)[2]["pending"] is None  # nothing was asked
    err = capfd.readouterr().err
    assert "internal error" not in err and "Traceback" not in err
    assert err.count("body did not arrive") == 1


def test_an_unauthenticated_body_is_never_read_and_its_connection_closes(tmp_path):
    with background(tmp_path / "s.corl", "synthetic", token=TOKEN) as url:
        with socket.create_connection(_address(url)) as s:
            s.sendall(b"POST /tell HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                      b"Content-Length: 1048576\r\nAuthorization: Bearer wrong\r\n\r\n")
            t0 = time.monotonic()
            s.settimeout(5)
            first = s.recv(65536)  # the 401 comes on the headers alone
            answered = time.monotonic() - t0
            took, _ = _until_closed(s, 5.0)
        assert first.startswith(b"HTTP/1.1 401 ") and answered < 0.5
        assert took < 2.0, took  # drained for a second at most, never held


def test_past_the_connection_cap_the_oldest_idle_connection_gives_way(tmp_path):
    limits = ServeLimits(header_timeout=30.0, max_connections=8)
    with background(tmp_path / "s.corl", "synthetic", limits=limits) as url:
        idle = _opened(url, 8, b"GET /sta")
        try:
            t0 = time.monotonic()
            status, _, body = _status(url)  # the 9th connection: answered, the oldest idle one closed
            assert status == 200 and body["trials"] == 0 and time.monotonic() - t0 < 1.0
            took, got = _until_closed(idle[0], 1.0)
            assert took != float("inf") and got.startswith(b"HTTP/1.1 503 ") and b"retry-after: 1" in got
            assert all(_until_closed(s, 0.05)[0] == float("inf") for s in idle[2:])  # the younger ones stay
        finally:
            for s in idle:
                s.close()


def test_past_the_request_cap_a_slow_body_gives_way_and_busy_requests_get_503(tmp_path):
    limits = ServeLimits(body_timeout=30.0, max_requests=2)
    with background(tmp_path / "s.corl", "synthetic", limits=limits) as url:
        slow = _opened(url, 2, b"POST /ask HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                               b"Content-Length: 100\r\n\r\n{")
        streams = []
        try:
            assert _status(url)[0] == 200  # a third request: the oldest slow body is closed for it
            assert _until_closed(slow[0], 1.0)[0] != float("inf")
            for _ in range(2):  # two event streams: requests in progress with no body to wait for
                c = http.client.HTTPConnection(*_address(url), timeout=5)
                c.request("GET", "/events")
                assert c.getresponse().status == 200
                streams.append(c)
            time.sleep(0.2)  # by now slow[1] has given way to the second stream
            status, headers, body = _status(url)
            assert status == 503 and headers.get("retry-after") == "1" and "retry in a second" in body["error"]
        finally:
            for s in slow:
                s.close()
            for c in streams:
                c.close()


def test_the_client_waits_out_a_busy_server_and_gives_up_after_retry_for(tmp_path):
    with background(tmp_path / "s.corl", "synthetic", limits=ServeLimits(max_requests=1)) as url:
        stream = http.client.HTTPConnection(*_address(url), timeout=5)
        stream.request("GET", "/events")  # the one request the server takes, in progress until closed
        assert stream.getresponse().status == 200
        with pytest.raises(ServerError, match="the most it takes; retry in a second") as refused:
            Client(url, retry_for=1.5).status()
        assert refused.value.status == 503
        threading.Timer(1.0, stream.close).start()
        t0 = time.monotonic()
        assert Client(url, retry_for=10).status()["trials"] == 0  # answered once the stream is gone
        assert 0.9 < time.monotonic() - t0 < 5.0


@pytest.fixture
def fresh_log():
    """The once-per-interval log filters forget what earlier tests' servers logged (they are per process)."""
    import logging

    from corl.serve.limits import OncePerInterval

    for name in ("uvicorn.error", "asyncio"):
        for f in logging.getLogger(name).filters:
            if isinstance(f, OncePerInterval):
                f._last.clear()
                f._held.clear()


def test_floods_of_bad_requests_write_one_line_per_interval(tmp_path, capfd, fresh_log):
    with background(tmp_path / "s.corl", "synthetic") as url:
        for _ in range(30):
            with socket.create_connection(_address(url)) as s:
                s.sendall(b"\x16\x03\x01 not http\r\n\r\n")
                _until_closed(s, 2.0)
        assert _status(url)[0] == 200
    err = capfd.readouterr().err
    assert err.count("Invalid HTTP request received") == 1, err


class _Loop:
    def __init__(self):
        self.default = []

    def default_exception_handler(self, context):
        self.default.append(context)


def test_accept_out_of_files_is_one_line_per_interval_and_frees_files(capsys):
    tracker = Tracker(ServeLimits(log_interval=60.0))
    loop = _Loop()
    error = OSError(errno.EMFILE, "Too many open files")
    for _ in range(500):  # asyncio calls the handler once per failed accept, up to the backlog per loop turn
        tracker.on_loop_error(loop, {"message": "socket.accept() out of system resource", "exception": error})
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot accept a connection (Too many open files)" in err
    other = {"message": "something else", "exception": ValueError("x")}
    tracker.on_loop_error(loop, other)
    assert loop.default == [other]  # anything else goes to asyncio's own handler


def test_serve_limits_are_checked_and_the_cap_follows_the_file_limit(tmp_path, monkeypatch):
    import resource

    for bad in (dict(header_timeout=0), dict(body_timeout=float("nan")), dict(max_connections=0),
                dict(max_requests=2.5), dict(log_interval="10")):
        with pytest.raises(InputError, match="ServeLimits"):
            ServeLimits(**bad)
    monkeypatch.setattr(resource, "getrlimit", lambda kind: (1024, 4096))
    assert ServeLimits().connections() == 1024 - 64 - 2 * 128
    monkeypatch.setattr(resource, "getrlimit", lambda kind: (100_000, 100_000))
    assert ServeLimits().connections() == 1000
    assert ServeLimits(max_connections=5).connections() == 5
    with pytest.raises(InputError, match="ServeLimits"):
        with background(tmp_path / "s.corl", "synthetic", limits={"max_requests": 3}):
            pass
    assert not (tmp_path / "s.corl").exists()
