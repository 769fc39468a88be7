"""What the run store holds: its error type, run and trial records, and how values are encoded.

Arrays are stored as raw little-endian float64 bytes beside their JSON shape (never pickled), so
they come back bit for bit; configurations and infos are stored as JSON text.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import datetime, timezone
from enum import Enum
from typing import Any

import numpy as np

from corl.errors import CorlError, InputError
from corl.problem import Outcome, Proposal

_ARRAY_DTYPE = np.dtype("<f8")


class StoreError(CorlError):
    """The run store cannot do what was asked (damaged file, second writer, trial told twice, ...)."""


class EmptyStoreError(StoreError):
    """Read-only open of a file that holds no store yet: empty, or its creation killed before the first commit."""


class RunStatus(str, Enum):
    """Where a run stands; a running run can be resumed, a finished one is only read."""

    RUNNING = "running"
    FINISHED = "finished"


@dataclass(frozen=True)
class RunInfo:
    """One run as listed by ``corl runs``; ``n_trials`` proposals stored, ``n_told`` of them told."""

    id: int
    created: str
    task: str
    method: str
    seed: int | None
    config: dict[str, Any]
    versions: dict[str, str]
    status: RunStatus
    n_trials: int
    n_told: int


@dataclass(frozen=True, eq=False)
class TrialRecord:
    """A stored trial: its proposal and, once told, its outcome (None while pending)."""

    proposal: Proposal
    outcome: Outcome | None
    proposed_at: str
    told_at: str | None

    @property
    def index(self) -> int:
        return self.proposal.index


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="microseconds")


def _json(value: Any, *, what: str) -> str:
    """JSON text of ``value``; numpy scalars and arrays become numbers and lists."""

    def plain(obj: Any) -> Any:
        if isinstance(obj, (np.generic, np.ndarray)):
            return obj.tolist()
        raise TypeError(f"a {type(obj).__name__} is not JSON-serializable")

    try:
        return json.dumps(value, default=plain)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be JSON-serializable to be stored: {exc}") from None


def _encode_array(value: Any, *, what: str) -> tuple[bytes, str]:
    """Little-endian float64 bytes and JSON shape of an array, e.g. ``w``: (n,)."""
    try:
        arr = np.ascontiguousarray(value, dtype=_ARRAY_DTYPE)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{what} must be an array of numbers to be stored: {exc}") from None
    return arr.tobytes(), json.dumps(list(arr.shape))


def _load_json(text: Any, *, what: str, kind: type | None = None) -> Any:
    """The value of a stored JSON field; a field that does not parse (or is not a ``kind``) is damage."""
    try:
        value = json.loads(text)
    except (TypeError, ValueError, RecursionError):
        raise StoreError(f"{what} is not valid JSON ({str(text)[:40]!r}); the store is damaged") from None
    if kind is not None and not isinstance(value, kind):
        raise StoreError(f"{what} holds a {type(value).__name__}, not a {kind.__name__}; the store is damaged")
    return value


def _decode_array(blob: bytes, shape_json: str, *, what: str) -> np.ndarray:
    shape = _load_json(shape_json, what=f"the shape of {what}", kind=list)
    if not all(isinstance(k, int) and not isinstance(k, bool) and 0 <= k < 2**31 for k in shape):
        raise StoreError(f"the shape of {what} is {shape}, not a list of sizes; the store is damaged")
    shape = tuple(shape)
    if not isinstance(blob, bytes):
        raise StoreError(f"{what} is stored as {type(blob).__name__}, not as bytes; the store is damaged")
    if len(blob) != _ARRAY_DTYPE.itemsize * int(np.prod(shape, dtype=np.int64)):
        raise StoreError(f"{what} has {len(blob)} bytes, which does not fit its shape {shape}; the store is damaged")
    return np.frombuffer(blob, dtype=_ARRAY_DTYPE).astype(np.float64).reshape(shape)


def _as_int(value: Any, *, what: str, minimum: int | None = None) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputError(f"{what} must be an integer, got {value!r}")
    value = int(value)
    if minimum is not None and value < minimum:
        raise InputError(f"{what} must be at least {minimum}, got {value}")
    if not -(2**63) <= value < 2**63:
        raise InputError(f"{what} is {value}, outside the 64-bit range a store holds")
    return value
