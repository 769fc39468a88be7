"""From joint-space waypoints to a demonstration ``(w0, theta0)`` that satisfies ``h(w0, theta0) = 0``.

Glossary
--------
times, knots  (K,) s and (K, Q): joint-space waypoints (e.g. from :func:`corl.mujoco.solve_waypoints`)
dt            s, the control step the dense reference is sampled at
w0            (n,) B-spline parameters fitted to the dense reference (least squares)
h             the task's Eq. 6 constraints ``h(w, theta0)`` (q,)

A B-spline fitted by least squares to waypoints joined piecewise-linearly passes *near* them, not
through them: the fitted demonstration misses its contact targets by millimetres. Alg. 1 assumes
``h(w0, theta0) = 0``; :func:`project_demonstration` moves w0 to the closest w on ``h = 0``
(Eq. 18 with :func:`corl.trajectory.project`) and reports how far it was.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from corl.errors import InputError, NumericalError
from corl.trajectory.bspline import BSpline

__all__ = ["piecewise_linear", "fit_demonstration", "ProjectionReport", "project_demonstration"]


def piecewise_linear(times, knots, duration: float, dt: float) -> np.ndarray:
    """Dense reference (N, Q) at ``dt``, linear between the knots, N = round(duration / dt) + 1.

    Parameters
    ----------
    times : (K,) increasing, s.
    knots : (K, Q).
    """
    times = np.asarray(times, dtype=float)
    knots = np.asarray(knots, dtype=float)
    if knots.ndim != 2 or times.shape != (knots.shape[0],):
        raise InputError(f"knots {knots.shape} need one time each, got times {times.shape}")
    if np.any(np.diff(times) <= 0):
        raise InputError("waypoint times must increase")
    t = np.arange(int(round(duration / dt)) + 1) * dt
    return np.stack([np.interp(t, times, knots[:, j]) for j in range(knots.shape[1])], axis=1)


def fit_demonstration(spline: BSpline, times, knots, dt: float) -> np.ndarray:
    """Least-squares B-spline parameters w0 (n,) of the piecewise-linear path through the knots.

    Parameters
    ----------
    spline : the task's BSpline (its ``duration`` and ``num_joints`` = Q).
    times : (K,) s; knots : (K, Q); dt : s, sampling step of the fit.
    """
    knots = np.asarray(knots, dtype=float)
    if knots.ndim != 2 or knots.shape[1] != spline.num_joints:
        raise InputError(f"knots have shape {knots.shape}, expected (K, {spline.num_joints}) for this spline")
    dense = piecewise_linear(times, knots, spline.duration, dt)
    t = np.arange(dense.shape[0]) * dt
    return spline.fit(t, dense)


@dataclass(frozen=True)
class ProjectionReport:
    """How far a demonstration was from ``h = 0`` and how much the projection moved it.

    Attributes
    ----------
    error_before, error_after : max |h| (the constraints' units, e.g. m) before and after.
    distance : ||w - w0||, parameter units.
    max_joint_change : largest change of any control point coordinate (rad or m).
    converged : the projection reached the solver's tolerance.
    """

    error_before: float
    error_after: float
    distance: float
    max_joint_change: float
    converged: bool

    def __str__(self) -> str:
        return (f"demonstration: max|h| = {self.error_before:.2e} before projection, {self.error_after:.2e} after; "
                f"w moved by {self.distance:.3g} (largest control-point change {self.max_joint_change:.3g})")


def project_demonstration(equalities: Callable, w0: np.ndarray, *, tolerance: float = 1e-6,
                          max_error: float | None = None) -> tuple[np.ndarray, ProjectionReport]:
    """Closest ``w`` to ``w0`` with ``h(w) = 0`` (Eq. 18), and a report of how far ``w0`` was.

    Parameters
    ----------
    equalities : ``w (n,) -> (h (q,), dh/dw (q, n))``, e.g. ``lambda w: task.constraint(w, theta0)``,
        or a :class:`corl.trajectory.TrajectoryProblem` (then solved on the banded SQP path).
    w0 : (n,) the fitted demonstration.
    tolerance : max |h| the projection must reach.
    max_error : refuse (InputError) a demonstration whose max |h| is above this before projection:
        it is not a small fitting error but a wrong demonstration or wrong constraints.

    Returns
    -------
    w : (n,) on ``h = 0``; report : ProjectionReport.
    """
    from corl.trajectory.solver import SolverConfig, project

    w0 = np.asarray(w0, dtype=float)
    fn = getattr(equalities, "equalities", equalities)
    h0, _ = fn(w0)
    before = float(np.max(np.abs(h0))) if np.size(h0) else 0.0
    if max_error is not None and before > max_error:
        raise InputError(f"the demonstration is {before:.3g} from h = 0 (max |h|), above max_error = {max_error:g}; "
                         "check its waypoints against the task's contact targets")
    result = project(equalities, w0, config=SolverConfig(tol_constraint=tolerance))
    h1, _ = fn(result.w)
    after = float(np.max(np.abs(h1))) if np.size(h1) else 0.0
    if not after <= max(tolerance, 1e-12) * 10:
        raise NumericalError(f"projecting the demonstration onto h = 0 stopped at max|h| = {after:.2e} "
                             f"({result.status}); the constraints may contradict each other or the start")
    report = ProjectionReport(error_before=before, error_after=after, distance=float(np.linalg.norm(result.w - w0)),
                              max_joint_change=float(np.max(np.abs(result.w - w0))), converged=bool(result.converged))
    return result.w, report
