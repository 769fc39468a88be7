"""Connections of ``corl serve`` under load: read deadlines, caps, and accept errors logged once.

uvicorn's h11 protocol (read in uvicorn 0.54) closes a keep-alive connection that stays idle after an
answer (``timeout_keep_alive``) but has no deadline for a request that is still arriving: a client
that sends ``GET /sta`` and waits holds its connection, and one of the process's files, for good.
Its ``limit_concurrency`` counts those idle connections too, so it would refuse everyone else. With
1,100 such connections and a file limit of 1,024, every ``accept()`` fails, asyncio logs a traceback
for each failed attempt (up to the backlog per loop turn: 34 MB of stderr in 10 s), and nobody is
served.

:class:`GuardedH11` is uvicorn's h11 protocol with the limits of :class:`corl.serve.limits.ServeLimits`,
counted in one :class:`Tracker` per server. A connection is in one of these phases:

=========  ======================================================  =============================
phase      what it waits for                                       deadline from the phase's start
=========  ======================================================  =============================
``head``   the rest of its request's headers (or a next request)   ``header_timeout``: 408, closed
``body``   the rest of its request's body                          ``body_timeout``: 408, closed
``linger`` nothing: answered before its body came (a 401, a 413)    1 s to read the answer, closed
(none)     its answer, being computed or streamed                  none
=========  ======================================================  =============================

A deadline runs from the start of its phase, so trickling one byte a second does not extend it.
The token is checked as soon as the headers are in (:class:`corl.serve.guard.Guard`), before a body
is read; an unauthenticated body is never read, only drained for ``linger``.

* **Connections.** Past ``max_connections`` (from the file limit), a new connection closes the oldest
  one still waiting in a phase (``linger`` first, then ``head``, then ``body``) with 503: an idle or
  slow client gives way to a new one. When every connection is being answered, the new one gets 503.
* **Requests.** Past ``max_requests`` requests in progress, a new request closes the oldest one still
  in ``body``, or gets 503 with ``Retry-After: 1``.
* **Malformed requests.** Bytes that are no HTTP/1.1 request get 400 with a one-line JSON error, as
  every other answer (uvicorn answers them in plain text), and the connection is closed.
* **Accept errors.** When ``accept()`` fails for lack of files anyway, the oldest waiting connections
  are closed to free some, and one line is written per ``log_interval``, where asyncio wrote a
  traceback per attempt.
"""

from __future__ import annotations

import asyncio
import errno
import json
import time
from collections import OrderedDict

import h11
from uvicorn.protocols.http.h11_impl import H11Protocol

from corl.serve.limits import ACCEPT_BATCH, Every, ServeLimits

__all__ = ["Tracker", "GuardedH11", "protocol_class", "HEAD", "BODY", "LINGER"]

HEAD, BODY, LINGER = "head", "body", "linger"
LINGER_S = 1.0  # an answer sent before the body arrived: the client has this long to read it
_OUT_OF_FILES = (errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM)
_REASONS = {400: "Bad Request", 408: "Request Timeout", 503: "Service Unavailable"}


def _answer(status: int, message: str) -> tuple[list[tuple[bytes, bytes]], bytes]:
    """Headers and body of a one-line JSON error that closes its connection (503: retry in a second)."""
    body = json.dumps({"error": message}).encode("utf-8")
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
               (b"cache-control", b"no-store"), (b"connection", b"close")]
    if status == 503:
        headers.append((b"retry-after", b"1"))
    return headers, body


class Tracker:
    """The connections of one server: how many are open, which wait in a phase (oldest first), how many
    requests are in progress; the limits they are held to and the rate-limited log of refusals."""

    def __init__(self, limits: ServeLimits) -> None:
        self.limits = limits
        self.max_connections = limits.connections()
        self.open = 0
        self.active = 0  # requests in progress: calls of the application
        self.waiting: dict[str, OrderedDict[GuardedH11, None]] = {HEAD: OrderedDict(), BODY: OrderedDict(),
                                                                  LINGER: OrderedDict()}
        self.log = Every(limits.log_interval)
        self._shed_at = -float("inf")

    def move(self, conn: "GuardedH11", old: str | None, new: str | None) -> None:
        if old is not None:
            self.waiting[old].pop(conn, None)
        if new is not None:
            self.waiting[new][conn] = None

    def oldest(self, phases=(LINGER, HEAD, BODY), exclude=None) -> "GuardedH11 | None":
        """The connection waiting longest in the first of ``phases`` that has one (not ``exclude``)."""
        for phase in phases:
            for conn in self.waiting[phase]:
                if conn is not exclude:
                    return conn
        return None

    def opened(self, conn: "GuardedH11") -> None:
        """Count a new connection; past the cap, close the oldest waiting one, or ``conn`` itself."""
        self.open += 1
        if self.open <= self.max_connections:
            return
        victim = self.oldest(exclude=conn)
        if victim is None:
            self.log.say("connections", f"{self.open - 1:,} connections are open and being answered, the most this "
                                        "server takes: a new one gets 503")
            conn.drop(503, f"the server has {self.max_connections:,} connections open, the most it takes; "
                           "retry in a second")
            return
        self.log.say("connections", f"{self.open:,} connections open, more than the {self.max_connections:,} the "
                                    "file limit leaves room for: closing the oldest that has not sent a whole request")
        victim.drop(503, f"the server has {self.max_connections:,} connections open and this one sent no whole "
                         "request; retry")

    def closed(self, conn: "GuardedH11") -> None:
        self.open -= 1

    def on_loop_error(self, loop: asyncio.AbstractEventLoop, context: dict) -> None:
        """The event loop's exception handler: ``accept()`` out of files is one line per interval, and
        closes the oldest waiting connections (at most ACCEPT_BATCH every half second) to free files."""
        exc = context.get("exception")
        if not (isinstance(exc, OSError) and exc.errno in _OUT_OF_FILES and "accept" in str(context.get("message"))):
            return loop.default_exception_handler(context)
        now = time.monotonic()
        shed = 0
        if now - self._shed_at >= 0.5:
            self._shed_at = now
            while shed < ACCEPT_BATCH and (victim := self.oldest()) is not None:
                victim.drop(503, "the server ran out of files; retry")
                shed += 1
        self.log.say("accept", f"cannot accept a connection ({exc.strerror}) with {self.open:,} open: raise the file "
                               f"limit (ulimit -n) or lower ServeLimits.max_connections; closed the {shed} oldest "
                               "that had not sent a whole request")


class GuardedH11(H11Protocol):
    """uvicorn's h11 protocol with read deadlines, a connection cap and a request cap (see the module)."""

    tracker: Tracker  # set on the subclass protocol_class() makes

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.phase: str | None = None
        self._deadline: asyncio.TimerHandle | None = None
        self._inner = self.app
        self.app = self._admit
        self._answered = 0

    # -- the connection, as asyncio sees it ---------------------------------------------------------
    def connection_made(self, transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self.tracker.opened(self)
        self._follow()

    def connection_lost(self, exc: Exception | None) -> None:
        self._enter(None)
        self.tracker.closed(self)
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        super().data_received(data)
        self._follow()

    def on_response_complete(self) -> None:
        self._answered += 1
        super().on_response_complete()
        self._follow()

    # -- phases and deadlines ------------------------------------------------------------------------
    def _follow(self) -> None:
        """Put the connection in the phase its request is in (a new phase starts a new deadline)."""
        if self.transport is None or self.transport.is_closing():
            return self._enter(None)
        theirs, ours = self.conn.their_state, self.conn.our_state
        if theirs is h11.IDLE:
            self._enter(HEAD)
        elif theirs is h11.SEND_BODY:
            self._enter(BODY if ours in (h11.SEND_RESPONSE, h11.SEND_BODY) else LINGER)
        else:  # the request is in: it is being answered (or the connection is closing)
            self._enter(None)

    def _enter(self, phase: str | None) -> None:
        if phase == self.phase:
            return
        self.tracker.move(self, self.phase, phase)
        self.phase = phase
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None
        limits = self.tracker.limits
        timeout = {HEAD: limits.header_timeout, BODY: limits.body_timeout, LINGER: LINGER_S}.get(phase)
        if timeout is not None:
            self._deadline = self.loop.call_later(timeout, self._expired)

    def _expired(self) -> None:
        self._deadline = None
        limits, log = self.tracker.limits, self.tracker.log
        if self.phase == HEAD:
            if self._answered and not self._started():  # an idle keep-alive connection: closed without a word
                return self.drop()
            log.say("head", f"closed a connection that sent no whole request header within {limits.header_timeout:g} s")
            self.drop(408, f"the request's headers did not arrive within {limits.header_timeout:g} s")
        elif self.phase == BODY:
            log.say("body", f"closed a request whose body did not arrive within {limits.body_timeout:g} s")
            self.drop(408, f"the request's body did not arrive within {limits.body_timeout:g} s")
        else:
            self.drop()

    def _started(self) -> bool:
        """Whether part of a next request has arrived (h11 holds bytes of it)."""
        return bool(self.conn.trailing_data[0])

    def drop(self, status: int | None = None, message: str = "") -> None:
        """Close the connection now; with ``status``, first answer a one-line JSON error to a request that has
        begun and has no answer yet (never to an idle connection: its client may be sending a request
        that would read the error as its answer)."""
        phase = self.phase
        self._enter(None)
        if self.transport is None or self.transport.is_closing():
            return
        begun = phase == BODY or (phase == HEAD and self._started())
        if status is not None and begun and self.conn.our_state in (h11.IDLE, h11.SEND_RESPONSE):
            headers, body = _answer(status, message)
            head = b"".join(k + b": " + v + b"\r\n" for k, v in headers)
            self.transport.write(b"HTTP/1.1 %d %s\r\n%s\r\n%s" % (status, _REASONS[status].encode(), head, body))
        self.transport.close()

    def send_400_response(self, msg: str) -> None:
        """uvicorn's answer to bytes h11 cannot read as a request, as one line of JSON like every answer
        (uvicorn's own is plain text), with the connection closed after it."""
        headers, body = _answer(400, f"{msg.rstrip('.')}: not a well-formed HTTP/1.1 request")
        for event in (h11.Response(status_code=400, headers=headers, reason=_REASONS[400].encode()),
                      h11.Data(data=body), h11.EndOfMessage()):
            self.transport.write(self.conn.send(event))
        self.transport.close()

    # -- the request cap -----------------------------------------------------------------------------
    async def _admit(self, scope, receive, send) -> None:
        """Run the application for this request, unless ``max_requests`` are in progress: then close the
        oldest request still sending its body, or answer 503."""
        tracker = self.tracker
        if tracker.active >= tracker.limits.max_requests:
            victim = tracker.oldest((BODY,), exclude=self)
            if victim is None:
                tracker.log.say("requests", f"{tracker.active} requests in progress, the most this server takes: "
                                            "a new one gets 503")
                headers, body = _answer(503, f"the server is answering {tracker.active} requests, the most it "
                                             "takes; retry in a second")
                await send({"type": "http.response.start", "status": 503, "headers": headers})
                await send({"type": "http.response.body", "body": body})
                return
            tracker.log.say("requests", f"{tracker.active} requests in progress, the most this server takes: closing "
                                        "the oldest one still sending its body")
            victim.drop(503, "the server is at its request limit and this request's body is the slowest; retry")
        tracker.active += 1
        try:
            await self._inner(scope, receive, send)
        finally:
            tracker.active -= 1


def protocol_class(tracker: Tracker) -> type[GuardedH11]:
    """The protocol class to give ``uvicorn.Config(http=...)``: :class:`GuardedH11` bound to ``tracker``."""
    return type("CorlH11Protocol", (GuardedH11,), {"tracker": tracker})
