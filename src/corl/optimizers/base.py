"""The one interface every black-box optimizer speaks: ``ask``, ``tell``, ``done``, ``best``.

PIBU, UCB, SAL, CMA-ES and PoWER all implement it, over ``theta`` inside CORL or over the full
``w`` as baselines. The CORL learner speaks the same protocol with :class:`corl.problem.Proposal`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from corl.errors import StateError
from corl.problem import Bounds, Outcome, check_theta

__all__ = ["BlackBoxOptimizer", "score_of"]


def score_of(outcome: Outcome, failure_return: float) -> float:
    """The scalar a method that ignores safety maximises: ``R`` on success, ``failure_return`` else."""
    return float(outcome.return_) if outcome.success else float(failure_return)


class BlackBoxOptimizer(ABC):
    """Maximises a black-box return over a box, one trial at a time.

    Subclasses implement :meth:`_propose` and :meth:`_observe`; this base class keeps the data,
    validates input and guards the ask/tell order. A proposal that was asked but not told is
    returned again by the next :meth:`ask` (a trial is never silently skipped).

    Attributes
    ----------
    bounds : the search box, (m,) each.
    X_ : (d, m) every point told so far; ``success_`` (d,) bool; ``returns_`` (d,) float (NaN where
        no return was observed).
    """

    def __init__(self, bounds: Bounds, *, max_evals: int = 100, name: str = "optimizer") -> None:
        self.bounds = bounds
        self.max_evals = int(max_evals)
        self.name = name
        m = bounds.dim
        self.X_ = np.empty((0, m))
        self.success_ = np.empty(0, dtype=bool)
        self.returns_ = np.empty(0)
        self._pending: np.ndarray | None = None
        self._stopped = False

    # -- the interface -------------------------------------------------------------------------
    def ask(self) -> np.ndarray:
        """Next point to evaluate, (m,). Raises :class:`StateError` when :attr:`done`."""
        if self._pending is not None:
            return self._pending.copy()
        if self.done:
            raise StateError(f"{self.name} has stopped; read .best instead of asking again")
        x = self._propose()
        if x is None:
            self._stopped = True
            raise StateError(f"{self.name} has converged; read .best instead of asking again")
        self._pending = self.bounds.clip(np.asarray(x, dtype=float).reshape(self.bounds.dim))
        return self._pending.copy()

    def tell(self, x: np.ndarray, outcome: Outcome) -> None:
        """Record the outcome of evaluating ``x`` (m,); ``x`` need not have been asked."""
        x = check_theta(x, self.bounds, task=self.name)
        if not isinstance(outcome, Outcome):
            raise StateError(f"tell needs an Outcome, got {type(outcome).__name__}")
        r = np.nan if outcome.return_ is None else float(outcome.return_)
        self.X_ = np.vstack([self.X_, x])
        self.success_ = np.append(self.success_, outcome.success)
        self.returns_ = np.append(self.returns_, r)
        if self._pending is not None and np.allclose(x, self._pending, rtol=0, atol=1e-12):
            self._pending = None
        self._observe(x, outcome)

    @property
    def done(self) -> bool:
        """True once the budget is spent or the method's own stopping rule fired."""
        return self._stopped or len(self.X_) >= self.max_evals

    @property
    def best(self) -> tuple[np.ndarray, float] | None:
        """The successful point with the highest return and that return, or None."""
        ok = self.success_ & np.isfinite(self.returns_)
        if not np.any(ok):
            return None
        idx = np.flatnonzero(ok)[np.argmax(self.returns_[ok])]
        return self.X_[idx].copy(), float(self.returns_[idx])

    @property
    def n_evals(self) -> int:
        return len(self.X_)

    # -- for subclasses ------------------------------------------------------------------------
    @abstractmethod
    def _propose(self) -> np.ndarray | None:
        """Next point (m,), or None when the method's stopping rule fires."""

    def _observe(self, x: np.ndarray, outcome: Outcome) -> None:
        """Hook called after each tell; the data is already in ``X_``, ``success_``, ``returns_``."""
