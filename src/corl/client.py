"""A client of ``corl serve`` that speaks like a learner: ``ask()``, ``tell()``, ``done``, ``stop_reason``, ``best``.

::

    from corl.client import Client

    c = Client("http://127.0.0.1:8765")          # token=... when the server has one
    while not c.done:
        trial = c.ask()                           # trial.t (K,), trial.q (K, Q): the joint trajectory
        success, ret = my_robot.execute(trial.t, trial.q)
        c.tell(success, ret)
    print(c.best, c.stop_reason)

Only the standard library is used (``http.client``, ``json``), so a robot's Python needs nothing
but corl itself. Both calls are idempotent on the server, so the client repeats them on its own
when the connection fails (a server restarted after a crash, a dropped network) or the server is
busy (503 with ``Retry-After``: at its limit of connections or requests): for up to ``retry_for``
seconds it retries, and a repeated ``tell`` of a trial the server already committed is answered
as the first one was. Errors the server answers (a bad outcome, a trial not pending,
a wrong token) raise at once with the server's one-line message.
"""

from __future__ import annotations

import http.client
import json
import time
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from corl.checks import flag, integer, number, text
from corl.errors import CorlError, InputError, StateError
from corl.problem import Outcome

__all__ = ["Client", "Trial", "RemoteBest", "ServerError"]


class ServerError(CorlError):
    """The server answered an error (``status`` is the HTTP status), or could not be reached in time."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


@dataclass(frozen=True)
class Trial:
    """A trial the server handed out.

    ``index`` its position in the run; ``theta`` (m,) its interaction parameters; ``step`` and
    ``round`` where in Algorithm 1 it comes from; ``t`` (K,) and ``q`` (K, Q) the joint trajectory
    to execute (``joint_names`` its columns) for a task with ``reference()``; ``w`` (n,) the raw
    parameters, only when asked for with ``raw=True`` (never send those to a robot); ``run`` the run
    it belongs to and ``context`` (k,) its scene, for a task with contexts (None otherwise).
    """

    index: int
    theta: np.ndarray
    step: str
    round: int
    t: np.ndarray | None = None
    q: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()
    w: np.ndarray | None = None
    run: int | None = None
    context: np.ndarray | None = None
    raw: dict = field(default_factory=dict, repr=False)  # the answer as it came


@dataclass(frozen=True)
class RemoteBest:
    """The learner's best so far (what to deploy): ``theta`` (m,), its estimated ``return_`` with ``return_std``
    (None when the estimate is one reading), analytic cost ``J`` and the ``trial`` whose motion it is. Not
    the highest reading: that is ``status()["best_observed"]``."""

    theta: np.ndarray
    return_: float
    J: float | None = None
    return_std: float | None = None
    trial: int | None = None


class Client:
    """Ask and tell trials of a ``corl serve`` at ``url`` (``http://host:port``).

    Parameters
    ----------
    url : the server's address, as ``corl serve`` prints it.
    token : the server's token (the content of its ``--token-file``), or None.
    raw : ask for the raw parameters w instead of a joint trajectory (a task without ``reference()``).
    timeout : seconds one request may take (an ask computes the next trial: give it time).
    retry_for : seconds to keep retrying a request whose connection failed, or that the server answered
        503 with ``Retry-After`` (busy; with several robots, all trials out): 0 fails at once.
    robot : this robot's name, sent with every ask (``corl serve --robots K``: 1-64 of ``[A-Za-z0-9_.-]``);
        ``ask(robot=...)`` overrides it.

    Notes
    -----
    Every argument is checked here, and every argument of :meth:`tell` before anything is sent: a
    wrong one raises a one-line :class:`corl.errors.InputError`.
    """

    def __init__(self, url: str, token: str | None = None, *, raw: bool = False, timeout: float = 600.0,
                 retry_for: float = 60.0, robot: str | None = None) -> None:
        text("Client(url)", url, spaces=False)
        parts = urlsplit(url)
        try:
            port = parts.port
        except ValueError:  # not a number, or beyond 65535
            port = 0
        if parts.scheme not in ("http", "https") or not parts.hostname or port == 0 or parts.query or parts.fragment:
            raise InputError(f"the server's url must look like http://127.0.0.1:8765 (a port in 1..65535), got {url!r}")
        self.url = url.rstrip("/")
        self._parts = parts
        self._prefix = parts.path.rstrip("/")  # a server behind a reverse proxy at http://host/corl
        self.token = None if token is None else text("Client(token)", token, spaces=False, ascii=True, secret=True)
        self.raw = flag("Client(raw)", raw)
        self.timeout = number("Client(timeout)", timeout, low=0.0, low_open=True)
        self.retry_for = number("Client(retry_for)", retry_for, low=0.0)
        self.robot = _robot("Client(robot)", robot)
        self._conn: http.client.HTTPConnection | None = None
        self._trial: Trial | None = None
        self._last: dict | None = None  # the latest status the server sent (a tell's answer carries it)

    # -- the learner's interface ---------------------------------------------------------------
    def ask(self, context=None, *, robot: str | None = None) -> Trial:
        """The next trial (the pending one again, when it was not told yet).

        ``context`` (k,): the scene the robot is in, for a task with contexts; the server then learns
        there (a new run that starts from every scene the store learned, or the scene's unfinished
        run). Refused while a trial of another scene is pending. None: the run the server serves now.
        ``robot``: the robot asking (default the client's ``robot``), for a server of several robots
        (``corl serve --robots K``): its own pending trial again, or a new one. While K trials are out
        the server answers 503 and this call waits and asks again, for up to ``retry_for`` seconds.
        """
        robot = self.robot if robot is None else _robot("ask(robot)", robot)
        body = {"raw": True} if self.raw else {}
        if robot is not None:
            body["robot"] = robot
        if context is not None:
            try:
                values = np.asarray(context, dtype=float).reshape(-1)
            except (TypeError, ValueError):
                raise InputError(f"ask(context=...) must be numbers, one per context coordinate, got {context!r:.60}") \
                    from None
            if not np.all(np.isfinite(values)):
                raise InputError(f"ask(context=...) must be finite numbers, got {values.tolist()}")
            body["context"] = values.tolist()
        a = self._request("POST", "/ask", body)
        ref = a.get("reference") or {}
        self._trial = Trial(index=int(a["trial"]), theta=np.asarray(a["theta"], dtype=float), step=a["step"],
                            round=int(a["round"]), run=a.get("run"),
                            t=None if "t" not in ref else np.asarray(ref["t"], dtype=float),
                            q=None if "q" not in ref else np.asarray(ref["q"], dtype=float),
                            joint_names=tuple(ref.get("joint_names", ())),
                            w=None if "w" not in a else np.asarray(a["w"], dtype=float),
                            context=None if a.get("context") is None else np.asarray(a["context"], dtype=float), raw=a)
        self._last = None
        return self._trial

    def tell(self, outcome: Outcome | bool, return_: float | None = None, *, info: dict | None = None,
             trial: int | None = None) -> dict:
        """Tell the outcome of the asked trial (or of ``trial``): an :class:`corl.Outcome`, or ``success, return_``."""
        if isinstance(outcome, Outcome):
            success, value, extra = outcome.success, outcome.return_, dict(outcome.info)
        else:
            success, value, extra = outcome, return_, {}
        success = flag("tell(success)", success)
        value = None if value is None else number("tell(return_)", value)
        if info is not None and not isinstance(info, dict):
            raise InputError(f"tell(info=...) must be a dict of JSON values, got {type(info).__name__}")
        extra.update(info or {})
        run = None
        if trial is None:
            if self._trial is None:
                raise StateError("tell() without ask(): ask for a trial first, run it, then tell its outcome")
            trial, run = self._trial.index, self._trial.run
        body = {"trial": integer("tell(trial)", trial), "success": success, "return": value, "info": extra}
        if run is not None:  # the run the trial came from: a server serving many scenes tells it there
            body["run"] = run
        answer = self._request("POST", "/tell", body)
        self._last = answer
        return answer

    @property
    def done(self) -> bool:
        """True once the learner stopped."""
        return bool(self._state()["done"])

    @property
    def stop_reason(self) -> str | None:
        """Why the learner stopped ("converged", "budget", ...), or None while it runs."""
        return self._state()["stop_reason"]

    @property
    def best(self) -> RemoteBest | None:
        """The learner's best so far (:class:`RemoteBest`), or None."""
        b = self.status().get("best")
        return None if b is None else RemoteBest(np.asarray(b["theta"], dtype=float), float(b["return"]), b.get("J"),
                                                 b.get("return_std"), b.get("trial"))

    def status(self) -> dict:
        """``GET /status``: trials, failures, pending, best, done, stop_reason."""
        self._last = self._request("GET", "/status")
        return self._last

    def trials(self, since: int = 0) -> list[dict]:
        """``GET /trials``: every trial from index ``since`` on."""
        return self._request("GET", f"/trials?since={integer('trials(since)', since)}")["trials"]

    def close(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- HTTP ----------------------------------------------------------------------------------
    def _state(self) -> dict:
        return self._last if self._last is not None and "done" in self._last else self.status()

    def _connection(self) -> http.client.HTTPConnection:
        if self._conn is None:
            kind = http.client.HTTPSConnection if self._parts.scheme == "https" else http.client.HTTPConnection
            self._conn = kind(self._parts.hostname, self._parts.port, timeout=self.timeout)
        return self._conn

    def _request(self, method: str, path: str, body: dict | None = None) -> dict[str, Any]:
        headers = {"Accept": "application/json"}
        data = None
        if body is not None:
            try:
                data = json.dumps(body, allow_nan=False).encode("utf-8")
            except (TypeError, ValueError) as exc:  # an info with NaN, an array, an object
                raise InputError(f"{path.lstrip('/')}: its info cannot be sent as JSON ({exc}); give strings, "
                                 "finite numbers, booleans, None, lists and dicts") from None
            headers["Content-Type"] = "application/json"
        if self.token is not None:
            headers["Authorization"] = f"Bearer {self.token}"
        deadline = time.monotonic() + self.retry_for
        delay = 0.05
        while True:
            try:
                conn = self._connection()
                conn.request(method, self._prefix + path, body=data, headers=headers)
                response = conn.getresponse()
                payload = response.read()
                status = response.status
                wait = _retry_after(response) if status == 503 else None
                if wait is None or time.monotonic() + wait > deadline:
                    break
                self.close()  # the server is at a limit of its connections or requests: once more, in a moment
                time.sleep(wait)
                continue
            except (ConnectionError, http.client.HTTPException, OSError) as exc:
                self.close()  # a fresh connection next time
                if time.monotonic() + delay > deadline:
                    raise ServerError(f"cannot reach the corl server at {self.url} ({type(exc).__name__}: {exc}); "
                                      "is corl serve running there?") from None
                time.sleep(delay)
                delay = min(2 * delay, 1.0)
        try:
            answer = json.loads(payload.decode("utf-8")) if payload else {}
        except (UnicodeDecodeError, ValueError):
            raise ServerError(f"{self.url}{path} answered {status} with something that is not JSON; is this a corl "
                              "server?", status) from None
        if status >= 400:
            message = answer.get("error", f"HTTP {status}") if isinstance(answer, dict) else f"HTTP {status}"
            if status == 400:
                raise InputError(message)
            if status == 409:
                raise StateError(message)
            raise ServerError(message, status)  # 401, 413, 415; 503 (the store, the learner; busy); 500 (the task)
        return answer


def _robot(what: str, name) -> str | None:
    """A robot's name (1-64 of ``[A-Za-z0-9_.-]``), or None; else one InputError."""
    import re

    if name is not None and not (isinstance(name, str) and re.fullmatch(r"[A-Za-z0-9_.-]{1,64}", name)):
        raise InputError(f"{what} must be a name of 1 to 64 letters, digits, '_', '.' or '-', got {name!r:.80}")
    return name


def _retry_after(response: http.client.HTTPResponse) -> float | None:
    """The seconds a 503 asks to wait before a retry (its ``Retry-After``, at most 5), or None when it asks none:
    a busy server says when to come back; a store that cannot commit does not."""
    value = response.getheader("Retry-After", "")
    return min(float(value), 5.0) if value.isascii() and value.isdigit() else None
