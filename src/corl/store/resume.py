"""Exact resume: :func:`replay` brings a fresh learner to where a stored run stopped."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from corl.errors import CorlError
from corl.problem import Outcome, Proposal
from corl.store.records import _ARRAY_DTYPE, StoreError
from corl.store.sqlite import RunStore
from corl.versions import library_versions, version_differences


class AskTellLearner(Protocol):
    """What :func:`replay` needs: the CORL learner's ``ask() -> Proposal`` and ``tell(outcome)``."""

    def ask(self) -> Proposal: ...

    def tell(self, outcome: Outcome) -> None: ...


def _bits_differ(asked: Any, stored: np.ndarray, what: str) -> str | None:
    """Why ``asked`` is not bit for bit ``stored``, or None when it is."""
    asked = np.asarray(asked, dtype=np.float64)
    if asked.shape != stored.shape:
        return f"{what} has shape {asked.shape}, the store holds {stored.shape}"
    if asked.astype(_ARRAY_DTYPE).tobytes() == stored.astype(_ARRAY_DTYPE).tobytes():
        return None
    gap = np.abs(asked - stored)
    j = int(np.nanargmax(gap)) if np.any(np.isfinite(gap)) else 0
    return f"{what} differs (largest difference {gap.flat[j]:.3g} at entry {j})"


def replay(learner: AskTellLearner, store: RunStore, run_id: int) -> int:
    """Bring a fresh learner to where a stored run stopped (exact resume).

    For each stored trial in index order (Alg. 1 replayed): ``p = learner.ask()`` must equal the
    stored proposal bit for bit (index, step, round, w, theta); a told trial is then told to the
    learner again. A final pending trial stays pending: the learner has asked it, so its next
    ``ask()`` returns it again and the loop executes it as if nothing had happened.

    The learner must be deterministic given its seed and freshly constructed with the run's task,
    method, seed and configuration. Returns the number of outcomes told.
    """
    records = store.trials(run_id)
    told = 0
    for i, record in enumerate(records):
        problem = None
        try:
            asked = learner.ask()
        except CorlError as exc:
            problem = f"the learner raised {type(exc).__name__} ({exc}) instead of proposing it"
        else:
            stored = record.proposal
            if (asked.index, asked.step, asked.round) != (stored.index, stored.step, stored.round):
                problem = (f"the learner proposed trial {asked.index} ({asked.step!r}, round {asked.round}), "
                           f"the store holds trial {stored.index} ({stored.step!r}, round {stored.round})")
            else:
                problem = _bits_differ(asked.w, stored.w, "w") or _bits_differ(asked.theta, stored.theta, "theta")
        if problem is not None:
            raise StoreError(_mismatch_message(store, run_id, i, problem))
        if record.outcome is None:
            if i != len(records) - 1:
                raise StoreError(f"trial {i} of run {run_id} is pending but later trials exist; the store is damaged")
            break
        learner.tell(record.outcome)
        told += 1
    return told


def _mismatch_message(store: RunStore, run_id: int, i: int, problem: str) -> str:
    run = store.run(run_id)
    message = (
        f"the store's run does not match this learner's configuration at trial {i}: {problem}. "
        f"Resume run {run_id} with a fresh learner built like the original: task {run.task!r}, "
        f"method {run.method!r}, seed {run.seed} and the stored configuration (`corl runs` shows it)"
    )
    changed = version_differences(run.versions, library_versions())
    if changed:
        message += "; the software also differs from the run's, which can change results: " + ", ".join(changed)
    return message
