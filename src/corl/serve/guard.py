"""Who may talk to a server: the loopback rule, the token, the Host header, the body's size and type.

* A server binds the loopback interface unless told otherwise, and a non-loopback bind needs a token
  (:func:`check_bind`): a learner that commits robot trials is never open to a whole network.
* With a token, every request carries ``Authorization: Bearer <token>``, compared in constant time
  (:func:`hmac.compare_digest`). A browser cannot set that header on a page load or an EventSource,
  so ``GET /?token=...`` sets an HttpOnly, SameSite=Strict cookie and redirects to ``/``; the cookie
  is accepted on GET requests only, so a web page elsewhere cannot make a browser ``tell`` a trial.
  The token is checked as soon as a request's headers are in, before its body is read; a refused
  request's body is never read, only drained for a second before its connection closes
  (:mod:`corl.serve.connections`).
* On a loopback bind the Host header must name a loopback address: a web page cannot reach the
  server through DNS rebinding (a name of its own that resolves to 127.0.0.1).
* A request body is JSON (``Content-Type: application/json``, which a cross-site form cannot send
  without the server's consent) of at most :data:`MAX_BODY_BYTES`.
"""

from __future__ import annotations

import hmac
import ipaddress
import os
import stat
from pathlib import Path

from corl.errors import InputError

__all__ = ["MAX_BODY_BYTES", "MIN_TOKEN_CHARS", "COOKIE", "is_loopback", "check_bind", "check_token", "read_token",
           "Guard",
           "HTTPProblem"]

MAX_BODY_BYTES = 1 << 20  # 1 MiB: a tell with a large info (a force trace) fits; anything larger is refused
MIN_TOKEN_CHARS = 16
MAX_TOKEN_FILE_BYTES = 4096  # a token file holds one token (a line of 43 characters from secrets.token_urlsafe)
COOKIE = "corl_token"
_TOKEN_HINT = "python3 -c 'import secrets; print(secrets.token_urlsafe(32))' > token.txt"


class HTTPProblem(Exception):
    """An HTTP error answered as ``{"error": message}`` with ``status`` (and extra headers)."""

    def __init__(self, status: int, message: str, headers: dict | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.headers = headers or {}


def is_loopback(host: str) -> bool:
    """True for ``localhost`` and the loopback addresses (127.0.0.0/8, ::1)."""
    host = host.strip("[]")
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def check_token(text: str, where: str = "the token") -> str:
    """``text`` if it is a usable token: at least 16 printable ASCII characters without spaces (InputError).

    ASCII, as :class:`corl.client.Client` requires: an HTTP header carries no other characters, so a
    token with an ``é`` could never be sent."""
    if not isinstance(text, str) or len(text) < MIN_TOKEN_CHARS or not text.isprintable() or \
            not text.isascii() or any(c.isspace() for c in text):
        raise InputError(f"{where} must hold one secret of at least {MIN_TOKEN_CHARS} printable ASCII characters "
                         f"without spaces; make one: {_TOKEN_HINT}")
    return text


def check_bind(host: str, token: str | None) -> None:
    """Refuse a non-loopback ``host`` without a token, and a token too weak to be one (InputError, one line)."""
    if token is not None:
        check_token(token)
    if not is_loopback(host) and token is None:
        raise InputError(f"corl serve listens on {host} only with a token, since anyone who reaches that address "
                         f"could tell trials: pass --token-file F (make one: {_TOKEN_HINT}), or drop --host to "
                         "listen on 127.0.0.1 only")


def read_token(path: str | Path) -> str:
    """The token in file ``path`` (surrounding whitespace dropped), checked: at least 16 printable ASCII
    characters. The file must be a regular file of at most :data:`MAX_TOKEN_FILE_BYTES` (a FIFO would
    block, ``/dev/zero`` never end)."""
    path = Path(path)
    try:  # opened without blocking (a FIFO would wait for a writer), then the open file itself is looked at
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as f:
            mode = os.fstat(f.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise InputError(f"--token-file {path} is not a regular file; give a file that holds the token "
                                 f"(make one: {_TOKEN_HINT})")
            data = f.read(MAX_TOKEN_FILE_BYTES + 1)  # one byte past the cap tells a file that is too long
        if len(data) > MAX_TOKEN_FILE_BYTES:
            raise InputError(f"--token-file {path} holds more than {MAX_TOKEN_FILE_BYTES} bytes; a token file holds "
                             f"one token (make one: {_TOKEN_HINT})")
        text = data.decode("utf-8").strip()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"--token-file {path} cannot be read ({getattr(exc, 'strerror', None) or exc}); "
                         f"make one: {_TOKEN_HINT}") from None
    check_token(text, f"--token-file {path}")
    if os.name == "posix" and mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise InputError(f"--token-file {path} can be read by other users (mode {stat.S_IMODE(mode):o}); "
                         f"chmod 600 {path}")
    return text


class Guard:
    """The checks every request passes before it reaches an endpoint (an ASGI middleware)."""

    def __init__(self, app, *, token: str | None, loopback: bool) -> None:
        self.app = app
        self.token = None if token is None else token.encode("utf-8")
        self.loopback = loopback

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        from starlette.requests import Request
        from starlette.responses import RedirectResponse

        from corl.serve.responses import problem_response

        request = Request(scope)
        try:
            self._check_host(request)
            if self.token is not None:
                if request.method == "GET" and request.url.path == "/" and "token" in request.query_params:
                    self._check(request.query_params["token"])
                    response = RedirectResponse("/", status_code=303)
                    response.set_cookie(COOKIE, request.query_params["token"], httponly=True, samesite="strict")
                    return await response(scope, receive, send)
                self._authorize(request)
        except HTTPProblem as exc:
            return await problem_response(exc)(scope, receive, send)
        await self.app(scope, receive, send)

    def _check_host(self, request) -> None:
        if not self.loopback:
            return
        host = request.headers.get("host", "")
        name = host.rsplit(":", 1)[0] if not host.endswith("]") else host
        if not is_loopback(name):
            raise HTTPProblem(400, f"the Host header {host[:80]!r} is not a loopback address; this server listens on "
                                   "loopback only: use http://127.0.0.1:PORT")

    def _authorize(self, request) -> None:
        header = request.headers.get("authorization", "")
        scheme, _, given = header.partition(" ")
        if header and scheme.lower() == "bearer":
            return self._check(given.strip())
        cookie = request.cookies.get(COOKIE)
        if cookie is not None and request.method in ("GET", "HEAD"):
            return self._check(cookie)
        raise HTTPProblem(401, "this server needs its token: send the header 'Authorization: Bearer <token>' "
                               "(corl.client.Client(url, token=...)), or open the dashboard at /?token=<token>",
                          {"WWW-Authenticate": 'Bearer realm="corl"'})

    def _check(self, given: str) -> None:
        if not hmac.compare_digest(given.encode("utf-8", "surrogateescape"), self.token):
            raise HTTPProblem(401, "wrong token: send the token in the server's --token-file",
                              {"WWW-Authenticate": 'Bearer realm="corl", error="invalid_token"'})
