"""corl.client.Client checks its arguments instead of converting them: each wrong one is a one-line
InputError raised before anything is sent (a listening socket that must see no connection stands in
for the server). The calls against a real server are in test_serve_api.py."""

from __future__ import annotations

import math
import socket

import pytest

from corl.client import Client
from corl.errors import InputError

TOKEN = "a-token-of-at-least-16-characters"


@pytest.fixture
def listener():
    """A socket that listens on loopback and answers nothing: a request would show as a connection."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(8)
        sock.settimeout(0.2)
        yield sock


def _nothing_sent(sock: socket.socket) -> bool:
    try:
        conn, _ = sock.accept()
    except socket.timeout:
        return True
    conn.close()
    return False


def _one_line(exc: pytest.ExceptionInfo) -> str:
    message = str(exc.value)
    assert "\n" not in message and len(message) < 200, message
    return message


@pytest.mark.parametrize("kwargs, match", [
    (dict(raw="no"), r"Client\(raw\) must be True or False, got 'no'"),
    (dict(raw=1), r"Client\(raw\) must be True or False"),
    (dict(retry_for=math.nan), r"Client\(retry_for\) must be a finite number, got nan"),
    (dict(retry_for=-1), r"Client\(retry_for\) must be in \[0, inf\)"),
    (dict(retry_for="60"), r"Client\(retry_for\) must be a number"),
    (dict(timeout=math.nan), r"Client\(timeout\) must be a finite number"),
    (dict(timeout=0), r"Client\(timeout\) must be in \(0, inf\)"),
    (dict(token=TOKEN + "\r\nX-Injected: 1"), r"Client\(token\) must be one line of printable ASCII characters"),
    (dict(token="with a space in the token"), r"without spaces"),
    (dict(token="tökén-of-the-lab-0123456789"), r"ASCII"),
    (dict(token=12345678901234567890), r"got a int"),
])
def test_a_wrong_setting_of_the_client_is_one_line(kwargs, match):
    with pytest.raises(InputError, match=match) as exc:
        Client("http://127.0.0.1:8765", **kwargs)
    message = _one_line(exc)
    assert "X-Injected" not in message and "tökén" not in message  # a token is never repeated


@pytest.mark.parametrize("url", ["http://127.0.0.1:99999", "http://127.0.0.1:abc", "http://127.0.0.1:0",
                                 "http://127.0.0.1:-1", "127.0.0.1:8765", "http://127.0.0.1:8765/x\r\nHost: evil",
                                 "http://127.0.0.1:8765/?token=x", None, b"http://127.0.0.1:8765"])
def test_a_url_that_names_no_server_is_one_line(url):
    with pytest.raises(InputError, match=r"url") as exc:
        Client(url)
    _one_line(exc)


@pytest.mark.parametrize("args, kwargs, match", [
    ((False,), dict(trial=1.9), r"tell\(trial\) must be a whole number, got 1.9"),
    ((False,), dict(trial=True), r"tell\(trial\) must be a whole number"),
    ((False,), dict(trial=-1), r"tell\(trial\) must be an integer >= 0"),
    ((True, "1_000"), dict(trial=1), r"tell\(return_\) must be a number, got '1_000'"),
    ((True, math.nan), dict(trial=1), r"tell\(return_\) must be a finite number"),
    ((True, math.inf), dict(trial=1), r"tell\(return_\) must be a finite number"),
    (("yes", 1.0), dict(trial=1), r"tell\(success\) must be True or False"),
    ((1, 1.0), dict(trial=1), r"tell\(success\) must be True or False"),
    ((True, 1.0), dict(trial=1, info=[1]), r"tell\(info=...\) must be a dict"),
    ((True, 1.0), dict(trial=1, info={"force": math.nan}), r"info cannot be sent as JSON"),
    ((True, 1.0), dict(trial=1, info={"trace": {1, 2}}), r"info cannot be sent as JSON"),
])
def test_a_wrong_tell_is_refused_before_anything_is_sent(listener, args, kwargs, match):
    c = Client(f"http://127.0.0.1:{listener.getsockname()[1]}", retry_for=0, timeout=1)
    with pytest.raises(InputError, match=match) as exc:
        c.tell(*args, **kwargs)
    _one_line(exc)
    with pytest.raises(InputError, match=r"trials\(since\) must be a whole number"):
        c.trials(since=1.5)
    assert _nothing_sent(listener)
