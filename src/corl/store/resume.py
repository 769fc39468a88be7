"""Exact resume: :func:`replay` brings a fresh learner to where a stored run stopped.

The stored proposals are what the robot executed, so they are the truth a resumed learner must
continue from. A learner rebuilt on another machine recomputes every proposal; another CPU (or
another OpenBLAS kernel on the same CPU) may round the last bits differently. A recomputed vector
``v`` that agrees with the stored ``s`` within

    max_j |v_j - s_j| <= RESUME_RTOL * max(1, max_j |s_j|)

is that same proposal: the stored values are copied into the learner's arrays in place, so the
learner continues from exactly what was executed and the replay stays exact. A larger difference
is a real divergence: the resume stops with a message that names the likely causes (library
versions, the BLAS kernel or processor, the code or configuration).

Glossary
--------
v, s        : a recomputed and the stored vector (``w`` (n,) or ``theta`` (m,))
RESUME_RTOL : tolerance relative to ``max(1, ||s||_inf)``. One rounding is ~1e-16, but the
              trajectory solvers stop at a tolerance (``SolverConfig.tol_constraint`` 1e-6,
              ``inner_rtol`` 1e-2), so another rounding can stop them a little elsewhere: measured
              on examples/planar_button.py (n = 90), the OpenBLAS Haswell kernel against SkylakeX
              moves every recomputed w by up to 2.4e-8 relative. Anything beyond the tolerance
              is taken for a real divergence (other code, configuration, seed or task).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from corl.errors import CorlError, TaskError
from corl.problem import Outcome, Proposal, task_error
from corl.store.machine import machine_info
from corl.store.records import _ARRAY_DTYPE, StoreError
from corl.store.sqlite import RunStore
from corl.versions import library_versions, version_differences

__all__ = ["RESUME_RTOL", "AskTellLearner", "replay", "way_on"]

RESUME_RTOL = 1e-6


class AskTellLearner(Protocol):
    """What :func:`replay` needs: the CORL learner's ``ask() -> Proposal`` and ``tell(outcome)``.

    The arrays of a proposal must be the learner's own (the ones it continues from): when a
    recomputed proposal agrees with the stored one within :data:`RESUME_RTOL`, replay overwrites
    them in place with the stored values. :class:`corl.CORL` and the methods over ``w`` do so.
    """

    def ask(self) -> Proposal: ...

    def tell(self, outcome: Outcome) -> None: ...


def _compare(asked: Any, stored: np.ndarray, what: str) -> tuple[str | None, bool]:
    """(why ``asked`` is not the stored vector, or None; whether it differs in its bits at all)."""
    arr = np.asarray(asked, dtype=np.float64)
    if arr.shape != stored.shape:
        return f"{what} has shape {arr.shape}, the store holds {stored.shape}", True
    if arr.astype(_ARRAY_DTYPE).tobytes() == stored.astype(_ARRAY_DTYPE).tobytes():
        return None, False
    gap = np.abs(arr - stored)
    scale = max(1.0, float(np.max(np.abs(stored), initial=0.0)))
    if np.all(np.isfinite(gap)) and float(np.max(gap)) <= RESUME_RTOL * scale:
        return None, True
    j = int(np.nanargmax(gap)) if np.any(np.isfinite(gap)) else 0
    return (f"{what} differs by {gap.flat[j]:.3g} at entry {j} (more than the {RESUME_RTOL:g} x {scale:.3g} "
            "that another CPU's rounding explains)"), True


def _adopt(asked: Proposal, stored: Proposal) -> str | None:
    """Copy the stored w and theta into the learner's arrays; why that is impossible, or None."""
    for mine, theirs, what in ((asked.w, stored.w, "w"), (asked.theta, stored.theta, "theta")):
        if not isinstance(mine, np.ndarray) or mine.dtype != np.float64 or not mine.flags.writeable:
            return (f"{what} agrees within {RESUME_RTOL:g} but differs in its last bits, and the learner's "
                    f"{what} is not a writable float64 array that could continue from the stored one")
        np.copyto(mine, theirs)
    return None


def replay(learner: AskTellLearner, store: RunStore, run_id: int) -> int:
    """Bring a fresh learner to where a stored run stopped (exact resume).

    For each stored trial in index order (Alg. 1 replayed): ``p = learner.ask()`` must propose the
    stored trial (same index, step and round; ``w`` and ``theta`` bit for bit or within
    :data:`RESUME_RTOL`, in which case the learner continues from the stored values); a told
    trial is then told to the learner again. A final pending trial stays pending: the learner has
    asked it, so its next ``ask()`` returns it again and the loop executes it as if nothing had
    happened. A run with K robots replays its asks, tells and waits in their stored order
    (:mod:`corl.store.meta`): its pending trials stay pending in the learner, each told when it comes.

    The learner must be deterministic given its seed and freshly constructed with the run's task,
    method, seed and configuration. Returns the number of outcomes told. Raises
    :class:`StoreError` naming the likely cause when the learner proposes something else, and
    :class:`TaskError` naming the task's member and the trial when the task's code raises; a run
    ended there (:meth:`RunStore.set_end`) stops at that error instead, the learner as it left it.
    """
    records = store.trials(run_id)
    end = store.end(run_id)
    pattern = store.pattern(run_id)
    if pattern is not None:
        return _replay_pattern(learner, store, run_id, records, pattern, end)
    told = 0
    for i, record in enumerate(records):
        _ask(learner.ask, store, run_id, records, i)
        if record.outcome is None:
            if i != len(records) - 1:
                raise StoreError(f"trial {i} of run {run_id} is pending but later trials exist; the store is damaged")
            break
        if _tell(lambda o: learner.tell(o), store, run_id, records, i, end):
            return told + 1
        told += 1
    return told


def _replay_pattern(learner, store: RunStore, run_id: int, records: list, pattern: str, end) -> int:
    """:func:`replay` of a run with K robots: its asks, tells and waits in their stored order
    (:mod:`corl.store.meta`), ``learner.try_ask()`` for an ask or a wait, ``learner.tell(outcome, index)``
    for a tell. The trials still pending stay pending in the learner (its ``pending``)."""
    order = store.told_order(run_id)
    if pattern.count("a") != len(records) or pattern.count("t") != len(order):
        raise StoreError(f"the pattern of run {run_id} names {pattern.count('a')} asks and {pattern.count('t')} tells, "
                         f"the store holds {len(records)} trials and {len(order)} outcomes; the store is damaged")
    asked = told = 0
    for letter in pattern:
        if letter == "t":
            i = order[told]
            if i >= asked:
                raise StoreError(f"trial {i} of run {run_id} was told before it was asked; the store is damaged")
            if _tell(lambda o: learner.tell(o, i), store, run_id, records, i, end):
                return told + 1
            told += 1
        elif letter == "a":
            _ask(learner.try_ask, store, run_id, records, asked)
            asked += 1
        else:
            try:
                extra = learner.try_ask()
            except CorlError:
                extra = None  # a learner that has finished: as the run found it
            if extra is not None:
                raise StoreError(_divergence_message(store, run_id, asked, f"the learner proposed trial {extra.index} "
                                                     "where the run found none to hand out"))
    return told


def _ask(ask, store: RunStore, run_id: int, records: list, i: int) -> Proposal:
    """``ask()`` must propose stored trial ``i`` (the learner continues from the stored arrays); else StoreError."""
    problem = None
    try:
        asked = ask()
    except CorlError as exc:
        problem = f"the learner raised {type(exc).__name__} ({exc}) instead of proposing it"
    except Exception as exc:
        error = _task_failed(exc, store, run_id, records, i, "as the learner worked out")
        if error is None:
            raise
        raise error from exc
    else:
        stored = records[i].proposal
        if asked is None:
            problem = "the learner had no trial to hand out"
        elif (asked.index, asked.step, asked.round) != (stored.index, stored.step, stored.round):
            problem = (f"the learner proposed trial {asked.index} ({asked.step!r}, round {asked.round}), "
                       f"the store holds trial {stored.index} ({stored.step!r}, round {stored.round})")
        else:
            problem_w, moved_w = _compare(asked.w, stored.w, "w")
            problem_theta, moved_theta = _compare(asked.theta, stored.theta, "theta")
            problem = problem_w or problem_theta
            if problem is None and (moved_w or moved_theta):
                problem = _adopt(asked, stored)
    if problem is not None:
        raise StoreError(_divergence_message(store, run_id, i, problem))
    return asked


def _tell(tell, store: RunStore, run_id: int, records: list, i: int, end) -> bool:
    """Tell the stored outcome of trial ``i``; True where the run was ended at a task error (it stops there)."""
    try:
        tell(records[i].outcome)
    except CorlError:
        raise
    except Exception as exc:
        if end is not None and end.get("trial") == i:  # where the run was ended: the learner stops as it did
            return True
        error = _task_failed(exc, store, run_id, records, i, "as the learner took in")
        if error is None:
            raise
        raise error from exc
    return False


def _task_failed(exc: Exception, store: RunStore, run_id: int, records: list, i: int, doing: str) -> TaskError | None:
    """The :class:`TaskError` of a replay whose learner met ``exc`` at trial ``i``, with the way on; None when
    ``exc`` did not come from the task's code."""
    error = task_error(exc, i, doing)
    if error is None:
        return None
    n_told = sum(r.outcome is not None for r in records)
    if i == len(records) - 1 and records[i].outcome is not None:  # where the run stopped when it ran
        way = way_on(store, run_id, error)
    else:
        way = (f"When the run went on past trial {i}, the task did not raise there: its code has changed since (or "
               "is not deterministic); restore it as it was, or start a new run")
    return TaskError(f"cannot resume run {run_id}: {error}; the store keeps all {n_told} told trials. {way}",
                     member=error.member, trial=error.trial, detail=error.detail)


def way_on(store: RunStore, run_id: int, error: TaskError) -> str:
    """What to do after the task's code raised on the run's last told trial ``error.trial``."""
    spec = store.run(run_id).config.get("task_spec", "TASK")
    return (f"Fix the task's {error.member} and resume (corl run --resume, corl ask, or restart corl serve), or end "
            f"the run at trial {error.trial}, keeping every trial: corl run {spec} --store {store.path} --resume "
            "--end-at-error")


def _divergence_message(store: RunStore, run_id: int, i: int, problem: str) -> str:
    """Where the resumed learner leaves the stored run, and what most likely made it."""
    run = store.run(run_id)
    message = f"cannot resume run {run_id}: the learner does not propose the stored trial {i}: {problem}. "
    here = {**library_versions(), **machine_info()}
    # A machine whose BLAS kernel cannot be read (older numpy builds) still differs from a run that named one.
    here.update({key: "unknown" for key in ("blas_kernel", "cpu") if key in run.versions and key not in here})
    changed = version_differences(run.versions, here)
    if changed:
        message += ("Likely cause: this machine's software or processor differs from the run's ("
                    + ", ".join(changed) + "); resume with the run's versions (`corl report` lists them)")
    else:
        message += ("The library versions and the BLAS kernel match the run's, so the likely cause is the code "
                    f"or the configuration: resume with the corl version, task {run.task!r}, method {run.method!r} "
                    f"and seed {run.seed} the run was started with")
    return message + ", or start a new run"
