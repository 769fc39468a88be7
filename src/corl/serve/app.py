"""The HTTP API of ``corl serve``: a Starlette application around one :class:`corl.serve.run.ServedRun`.

=========================  =========================================================================
``POST /ask``              the next trial (the pending one while one is pending); ``{"raw": true}``
                           for the raw parameters w of a task without ``reference()``; with
                           ``--robots K``, ``{"robot": "name"}``: that robot's trial (:mod:`corl.serve.fleet`)
``POST /tell``             ``{"trial": i, "success": bool, "return": float | null, "info": {...}}``
``GET /status``            trials, failures, pending, best, done, stop_reason (K robots: pending_trials,
                           pending_robots, robots)
``GET /trials?since=k``    the trials from index k on
``GET /events``            server-sent events: ``status`` on every change, ``figures`` when redrawn
``GET /figures/NAME.png``  the dashboard's figures (``trials``, ``return_map``), drawn as ``corl report`` draws
``GET /video``             the video of the last told trial, for a task that renders one
``GET /``                  the live dashboard
=========================  =========================================================================

The learner runs in a worker thread behind the run's lock, so the dashboard and ``/status`` answer
while a trial is computed. Each ask and tell answer carries ``Server-Timing`` (``compute``: the
learner and the reference; ``commit``: the store), so a client can tell network time from work.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import sys
from importlib import resources

from corl.errors import CorlError, InputError
from corl.serve.fleet import Busy
from corl.serve.guard import MAX_BODY_BYTES, Guard, HTTPProblem
from corl.serve.responses import json_response, one_line, problem_response
from corl.serve.run import Broken, Conflict, ServedRun, TaskCodeError

__all__ = ["create_app", "Notifier"]

_KEEPALIVE_S = 15.0


class Notifier:
    """Wakes every waiting event stream when the run or its figures change (callable from any thread)."""

    def __init__(self) -> None:
        self.loop: asyncio.AbstractEventLoop | None = None
        self._event: asyncio.Event | None = None
        self.subscribers = 0
        self.closing = False

    def close(self) -> None:
        """End every event stream (the server is stopping): safe from any thread."""
        self.closing = True
        self.notify()

    def bind(self) -> None:
        self.loop = asyncio.get_running_loop()
        self._event = asyncio.Event()

    def notify(self) -> None:
        """Wake the waiters; safe from a worker thread."""
        if self.loop is None:
            return
        try:
            self.loop.call_soon_threadsafe(self._wake)
        except RuntimeError:  # the loop has closed: the server is stopping
            pass

    def _wake(self) -> None:
        event, self._event = self._event, asyncio.Event()
        event.set()

    async def wait(self, timeout: float) -> None:
        event = self._event
        try:
            await asyncio.wait_for(event.wait(), timeout)
        except asyncio.TimeoutError:
            pass


async def _read_json(request) -> dict:
    """The request's JSON object; 415 for another type, 413 beyond MAX_BODY_BYTES, 400 when malformed."""
    length = request.headers.get("content-length")
    if length is not None and (not length.isdigit() or int(length) > MAX_BODY_BYTES):
        raise HTTPProblem(413, f"the body is larger than {MAX_BODY_BYTES} bytes; send less info with the trial")
    from starlette.requests import ClientDisconnect

    chunks, size = [], 0
    try:
        async for chunk in request.stream():
            size += len(chunk)
            if size > MAX_BODY_BYTES:
                raise HTTPProblem(413, f"the body is larger than {MAX_BODY_BYTES} bytes; send less info with the trial")
            chunks.append(chunk)
    except ClientDisconnect:  # gone, or closed past its body's deadline (corl.serve.connections): nobody to answer
        raise HTTPProblem(408, "the connection closed before the request's body arrived") from None
    data = b"".join(chunks)
    kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if kind != "application/json":  # also for an empty body: a cross-site form cannot send this type
        raise HTTPProblem(415, f"a POST needs 'Content-Type: application/json' (and a JSON body, {{}} for none), "
                               f"got {kind or 'none'!r}")
    if not data.strip():
        return {}

    def refuse(token):
        raise ValueError(f"{token} is not a number JSON allows")

    def finite(text):
        value = float(text)
        if not math.isfinite(value):
            raise ValueError(f"{text[:40]} is beyond a float's range")
        return value

    try:
        return json.loads(data.decode("utf-8"), parse_constant=refuse, parse_float=finite)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise HTTPProblem(400, f"the body is not valid JSON: {one_line(str(exc), 120)}") from None


def _timing_header(timing) -> dict:
    return {"Server-Timing": f"compute;dur={timing.compute * 1e3:.3f}, commit;dur={timing.commit * 1e3:.3f}"}


def _status_of(exc: BaseException) -> int:
    """400: the request; 409: the run's state; 503: the store or the learner, worth a retry after a fix
    (a full disk, a learner that raised); 500: the task's code or corl itself."""
    from corl.store import StoreError

    if isinstance(exc, HTTPProblem):
        return exc.status
    if isinstance(exc, Conflict):
        return 409
    if isinstance(exc, (Broken, StoreError, Busy)):
        return 503
    if isinstance(exc, TaskCodeError):
        return 500
    if isinstance(exc, InputError):
        return 400
    if isinstance(exc, CorlError):
        return 409 if isinstance(exc, RuntimeError) else 400
    return 500


def create_app(run: ServedRun, *, token: str | None = None, loopback: bool = True, figures=None, video=None):
    """The ASGI application serving ``run``; ``figures``/``video`` (:mod:`corl.serve.dashboard`) draw its pages."""
    from starlette.applications import Starlette
    from starlette.exceptions import HTTPException
    from starlette.middleware import Middleware
    from starlette.responses import FileResponse, HTMLResponse, Response, StreamingResponse
    from starlette.routing import Route

    notifier = Notifier()
    if figures is not None:
        figures.notify = notifier.notify
    if video is not None:
        video.notify = notifier.notify

    def changed() -> None:
        notifier.notify()
        if notifier.subscribers and figures is not None:
            figures.want()

    async def guarded(call, request, *, body: bool):
        version = run.version
        try:
            payload = await _read_json(request) if body else {}
            answer, timing = await asyncio.get_running_loop().run_in_executor(run.executor, call, payload)
        except (Exception, SystemExit) as exc:  # every error is one JSON line; a task's sys.exit() too
            status = _status_of(exc)
            if status == 500 and not isinstance(exc, TaskCodeError):
                print(f"corl serve: internal error {type(exc).__name__}: {one_line(str(exc), 300)}", file=sys.stderr)
                message = f"internal error ({type(exc).__name__}: {exc}); the store keeps every told trial"
            else:
                message = str(exc)
            retry = {"Retry-After": str(exc.retry_after)} if isinstance(exc, Busy) else None  # K trials out
            if run.version != version:  # refused, but the run moved (K robots: Algorithm 1 ended as it was asked)
                changed()
            return problem_response(HTTPProblem(status, message, retry))
        changed()
        return json_response(answer, headers=_timing_header(timing))

    async def ask(request):
        return await guarded(run.ask, request, body=True)

    async def tell(request):
        response = await guarded(run.tell, request, body=True)
        if response.status_code == 200 and video is not None:
            video.want(run)
        return response

    async def status(request):
        return json_response(run.status)

    async def trials(request):
        since = request.query_params.get("since", "0")
        if not (since.isascii() and since.isdigit() and len(since) <= 12):
            return problem_response(HTTPProblem(400, f"'since' must be a trial index (an integer >= 0), got {since!r:.40}"))
        return json_response({"run": run.session.run_id, "trials": run.trials(int(since))})

    async def events(request):
        if request.method == "HEAD":  # headers only: a stream that never ends has no length to tell
            return Response(media_type="text/event-stream", headers={"Cache-Control": "no-store"})

        async def stream():
            notifier.subscribers += 1
            if figures is not None:
                figures.want()
            sent = fig_sent = video_sent = None
            try:
                while not notifier.closing:
                    if run.version != sent:
                        sent = run.version
                        yield f"event: status\ndata: {json.dumps(run.status)}\n\n"
                    if figures is not None and figures.version != fig_sent:
                        fig_sent = figures.version
                        yield f"event: figures\ndata: {json.dumps(figures.describe())}\n\n"
                    if video is not None and video.version != video_sent:
                        video_sent = video.version
                        yield f"event: video\ndata: {json.dumps(video.describe())}\n\n"
                    await notifier.wait(_KEEPALIVE_S)
                    if notifier.closing:
                        break
                    if run.version == sent and (figures is None or figures.version == fig_sent) and \
                            (video is None or video.version == video_sent):
                        yield ": keep-alive\n\n"
            finally:
                notifier.subscribers -= 1

        return StreamingResponse(stream(), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-store", "X-Accel-Buffering": "no"})

    async def figure(request):
        name = request.path_params["name"]
        png = None if figures is None else figures.png.get(name)
        if png is None:
            note = None if figures is None else figures.notes.get(name)
            return problem_response(HTTPProblem(404, note or f"figure {name!r} is not drawn (yet)"))
        return Response(png, media_type="image/png", headers={"Cache-Control": "no-store"})

    async def video_file(request):
        path = None if video is None else video.path
        if path is None:
            return problem_response(HTTPProblem(404, "no video (yet): the task renders none, or none is rendered"))
        return FileResponse(path, media_type="video/mp4", headers={"Cache-Control": "no-store"})

    page = resources.files("corl.serve") / "static"

    async def dashboard(request):
        return HTMLResponse((page / "dashboard.html").read_text(encoding="utf-8"),
                            headers={"Cache-Control": "no-store"})

    async def asset(request):
        name = request.path_params["name"]
        kinds = {"dashboard.js": "text/javascript", "dashboard.css": "text/css"}
        if name not in kinds:
            return problem_response(HTTPProblem(404, f"no asset {name!r:.60}"))
        return Response((page / name).read_text(encoding="utf-8"), media_type=kinds[name])

    async def http_error(request, exc):
        allow = {"Allow": exc.headers["Allow"]} if exc.headers and "Allow" in exc.headers else {}
        where = f"{request.method} {request.url.path}"[:120]
        message = {404: f"no such endpoint: {where}; see GET / or the docs' server guide",
                   405: f"{where} is not allowed; this endpoint takes {allow.get('Allow', 'another method')}"}
        return problem_response(HTTPProblem(exc.status_code, message.get(exc.status_code, str(exc.detail)), allow))

    @contextlib.asynccontextmanager
    async def lifespan(app):
        notifier.bind()
        if figures is not None:
            figures.start(run)
        try:
            yield
        finally:
            for part in (figures, video):
                if part is not None:
                    part.stop()

    routes = [Route("/ask", ask, methods=["POST"]), Route("/tell", tell, methods=["POST"]),
              Route("/status", status, methods=["GET"]), Route("/trials", trials, methods=["GET"]),
              Route("/events", events, methods=["GET"]), Route("/figures/{name}.png", figure, methods=["GET"]),
              Route("/video", video_file, methods=["GET"]), Route("/", dashboard, methods=["GET"]),
              Route("/static/{name}", asset, methods=["GET"])]
    app = Starlette(routes=routes, middleware=[Middleware(Guard, token=token, loopback=loopback)],
                    exception_handlers={HTTPException: http_error}, lifespan=lifespan)
    app.state.notifier = notifier
    return app
