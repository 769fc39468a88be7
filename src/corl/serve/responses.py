"""JSON answers of the server: every error is ``{"error": "<one line>"}`` with its status, never a traceback."""

from __future__ import annotations

import json
import math

__all__ = ["json_response", "problem_response", "one_line"]


def one_line(message: str, limit: int = 500) -> str:
    """``message`` on one line, at most ``limit`` characters."""
    text = " ".join(str(message).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _plain(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    return obj


def json_response(payload, status: int = 200, headers: dict | None = None):
    """A JSON response; non-finite floats become null (JSON has no NaN)."""
    from starlette.responses import Response

    body = json.dumps(_plain(payload), allow_nan=False, separators=(",", ":"))
    return Response(body, status_code=status, media_type="application/json",
                    headers={"Cache-Control": "no-store", **(headers or {})})


def problem_response(problem):
    """The response of an :class:`corl.serve.guard.HTTPProblem`."""
    return json_response({"error": one_line(str(problem))}, problem.status, problem.headers)
