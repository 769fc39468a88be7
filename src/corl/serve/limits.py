"""How much a server takes at once, and how long a request may take to arrive.

A server on a network it does not trust meets clients that open connections and never finish a
request (a flood of ``GET /sta``), send their headers a byte a second, or announce a 1 MiB body and
trickle it. :class:`ServeLimits` bounds each: a deadline for the headers, one for the body, a cap on
open connections (from the process's file limit) and one on requests in progress.
:mod:`corl.serve.connections` enforces them; this module needs nothing beyond corl.

:class:`Every` and :class:`OncePerInterval` keep a flood from flooding stderr too: a refusal of the
same kind is written at most once per interval, with the count of those held back.
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import dataclass

from corl.checks import integer, number

__all__ = ["ServeLimits", "Every", "OncePerInterval", "ACCEPT_BATCH", "FILES_KEPT"]

ACCEPT_BATCH = 128  # the listen backlog; asyncio accepts up to this many connections per loop turn
FILES_KEPT = 64  # files kept free of connections: the store, its journal, pipes of the figure processes
MOST_CONNECTIONS = 1000  # the cap when the file limit allows more; a robot's server needs a handful


@dataclass(frozen=True)
class ServeLimits:
    """Deadlines and caps of one server.

    Parameters
    ----------
    header_timeout : seconds from a connection's opening (or its previous answer) to the end of its
        request's headers. Trickling a byte at a time does not extend it.
    body_timeout : seconds from the end of the headers to the body's last byte (1 MiB at 100 kB/s fits).
    max_connections : connections open at once; None: as many as the file limit leaves room for
        (limit - 64 - 2 x 128), at most 1,000. Past it, a new connection closes the oldest one that
        has not sent a whole request yet.
    max_requests : requests in progress at once (a dashboard's event stream is one). Past it, a new
        request closes the oldest one still sending its body, or gets 503 with ``Retry-After: 1``.
    log_interval : seconds between two stderr lines about the same kind of refusal.
    """

    header_timeout: float = 5.0
    body_timeout: float = 10.0
    max_connections: int | None = None
    max_requests: int = 64
    log_interval: float = 10.0

    def __post_init__(self) -> None:
        for name in ("header_timeout", "body_timeout", "log_interval"):
            object.__setattr__(self, name, number(f"ServeLimits.{name}", getattr(self, name), low=0.0,
                                                  low_open=True))
        if self.max_connections is not None:
            object.__setattr__(self, "max_connections", integer("ServeLimits.max_connections",
                                                                self.max_connections, low=1))
        object.__setattr__(self, "max_requests", integer("ServeLimits.max_requests", self.max_requests, low=1))

    def connections(self) -> int:
        """``max_connections``, or what this process's file limit leaves room for (at least 16)."""
        if self.max_connections is not None:
            return self.max_connections
        try:
            import resource
        except ImportError:  # not POSIX: no file limit to read
            return MOST_CONNECTIONS
        soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
        if soft == resource.RLIM_INFINITY:
            return MOST_CONNECTIONS
        # a loop turn accepts up to ACCEPT_BATCH sockets before any is counted, and as many may be closing
        return max(16, min(MOST_CONNECTIONS, soft - FILES_KEPT - 2 * ACCEPT_BATCH))


class Every:
    """Write ``corl serve: <message>`` on stderr at most once per ``interval`` seconds per kind of event;
    the next line written says how many were held back since the last."""

    def __init__(self, interval: float, stream=None) -> None:
        self.interval = interval
        self.stream = stream
        self._last: dict[str, float] = {}
        self._held: dict[str, int] = {}

    def say(self, kind: str, message: str) -> bool:
        """Write ``message`` unless one of ``kind`` was written less than ``interval`` ago; True if written."""
        now = time.monotonic()
        last = self._last.get(kind)
        if last is not None and now - last < self.interval:
            self._held[kind] = self._held.get(kind, 0) + 1
            return False
        held = self._held.pop(kind, 0)
        self._last[kind] = now
        more = f" ({held:,} more like it in the last {now - last:.0f} s)" if held else ""
        print(f"corl serve: {message}{more}", file=self.stream or sys.stderr, flush=True)
        return True


class OncePerInterval(logging.Filter):
    """A logging filter: a record whose message template was let through less than ``interval`` seconds
    ago is dropped (uvicorn's 'Invalid HTTP request received.' once per bad connection, asyncio's tracebacks)."""

    def __init__(self, interval: float) -> None:
        super().__init__()
        self.interval = interval
        self._last: dict[tuple, float] = {}
        self._held: dict[tuple, int] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        key = (record.name, record.levelno, str(record.msg))
        now = time.monotonic()
        last = self._last.get(key)
        if last is not None and now - last < self.interval:
            self._held[key] = self._held.get(key, 0) + 1
            return False
        self._last[key] = now
        held = self._held.pop(key, 0)
        if held:
            record.msg = f"{record.getMessage()} ({held:,} more like it in the last {now - last:.0f} s)"
            record.args = None
        return True

    @classmethod
    def attach(cls, interval: float, names=("uvicorn.error", "asyncio")) -> None:
        """Put one filter on each logger in ``names`` (once: a second server in the process reuses it)."""
        for name in names:
            logger = logging.getLogger(name)
            if not any(isinstance(f, cls) for f in logger.filters):
                logger.addFilter(cls(interval))
