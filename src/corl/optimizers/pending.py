"""Several trials out at once: keeping a safe method's next proposal apart from the pending ones.

Glossary
--------
out    : (p, m) points handed out by ``ask`` and not told yet (K robots: p < K)
radius : (m,) half-axes of the ellipsoid around each pending point where no proposal goes
"""

from __future__ import annotations

import numpy as np

__all__ = ["AwayFromPending", "apart", "for_fleet", "PENDING_RADIUS", "PENDING_FALLBACK", "P_PENDING"]

#: Several trials out at once: no proposal within this many of g_S's length scales (per dimension, an
#: ellipsoid) of a pending trial, where that trial's outcome will soon tell most of what another would.
#: Safety needs no fantasy: every proposal is in SEIB's band under the data told, whatever the pending
#: trials' outcomes (g_S is never told a success that has not happened). Measured on the synthetic task
#: (corl bench parallel synthetic --robots 4 --trial-seconds 0.5 --no-rollout-every-step, seed 0):
#: 0.5 -> wall 0.87x one robot's, 40 trials, 2 failures; 0.25 -> 0.68x, 52 trials, 1 failure, final
#: return 0.99977 (one robot 0.9999998); 0.1 -> 0.58x, 52 trials, 1 failure, 0.9983 (proposals that
#: close tell little more than one).
PENDING_RADIUS = 0.25
PENDING_FALLBACK = 0.05  # box widths, for a g_S without length scales
#: At most one trial whose success g_S doubts (p below this) is out at a time: while one is, a
#: further proposal needs p >= this (one robot's proposals need SEIB's band, p >= 0.55). Measured
#: on the door (corl bench parallel door --robots 4 --trial-seconds 0.5, seed 0; one robot: 8
#: failures, final return 0.571): without it 17 failures, 0.544; 0.7 -> 8, 0.537; 0.8 -> 4, 0.519.
#: On the synthetic task's black-box step alone (--no-rollout-every-step) it costs wall time: 0.68x
#: one robot's without it, 0.97x with it (more trials wait for a tell).
P_PENDING = 0.7


class AwayFromPending:
    """``acquisition`` with 0 within ``radius`` (m,) (ellipsoidal) of each pending point ``out`` (p, m)."""

    def __init__(self, acquisition, out: np.ndarray, radius: np.ndarray) -> None:
        self.acquisition, self.out, self.radius = acquisition, np.asarray(out, dtype=float), np.asarray(radius, float)

    def __getattr__(self, name):  # boundary_level, parts, ... of the acquisition
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.acquisition, name)

    def _far(self, X: np.ndarray) -> np.ndarray:
        d = np.linalg.norm((np.asarray(X, dtype=float)[:, None, :] - self.out[None]) / self.radius, axis=2)
        return np.min(d, axis=1) >= 1.0

    def __call__(self, X: np.ndarray) -> np.ndarray:
        return np.where(self._far(X), np.asarray(self.acquisition(X), dtype=float), 0.0)

    def on_lattice(self, X: np.ndarray, axes) -> np.ndarray:
        on_lattice = getattr(self.acquisition, "on_lattice", None)
        values = self.acquisition(X) if on_lattice is None else on_lattice(X, axes)
        return np.where(self._far(X), np.asarray(values, dtype=float), 0.0)


def apart(acquisition, out: np.ndarray, classifier, bounds):
    """``acquisition`` kept away from the pending trials ``out`` (p, m); as it is with none.

    The radius is :data:`PENDING_RADIUS` of ``classifier``'s (g_S's) length scales, or
    :data:`PENDING_FALLBACK` box widths for a classifier without them.
    """
    if not len(out):
        return acquisition
    lengths = getattr(getattr(getattr(classifier, "_model", None), "kernel_", None), "lengthscales", None)
    radius = PENDING_FALLBACK * bounds.width if lengths is None else PENDING_RADIUS * lengths * np.ones(len(out[0]))
    return AwayFromPending(acquisition, out, radius)


def for_fleet(acquisition, out: np.ndarray, classifier, bounds, failed=None, tolerance: float = 0.0):
    """``acquisition`` as a safe method asks it with the trials ``out`` (p, m) pending:

    * 0 within ``tolerance`` box widths of every ``failed`` point (k, m), if given: never asked again;
    * while a pending trial has g_S's p below :data:`P_PENDING`, -inf where p is below it too (at
      most one trial whose success g_S doubts is out at a time);
    * kept apart from the pending trials (:func:`apart`).
    """
    from corl.acquisition.guarded import Guarded

    if failed is not None and len(failed):
        acquisition = AwayFromPending(acquisition, failed, tolerance * bounds.width * np.sqrt(bounds.dim))
    if len(out) and np.any(classifier.predict_proba(out) < P_PENDING):
        acquisition = Guarded(acquisition, lambda P: classifier.predict_proba(np.asarray(P, float)) >= P_PENDING)
    return apart(acquisition, out, classifier, bounds)
