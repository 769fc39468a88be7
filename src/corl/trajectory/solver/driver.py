"""The two entry points of the solver: :func:`solve` (Eq. 8) and :func:`project` (Eq. 18's machinery).

Alg. 1, step 1 improves the trajectory parameters on the analytic cost while the constraint h
keeps theta fixed and a ball limits the change (Eq. 8)::

    w^(i+1) = argmin_w J(w)   s.t.  h(w) = 0,  ||w - w^(i)|| <= eps_max,    J(w) = r(w)^T r(w)  (Eq. 7)

:func:`solve` evaluates the start (:class:`~corl.trajectory.solver.model.Iterate`), builds the
shared :class:`~corl.trajectory.solver.state.SolveState` and picks the strategy: SQP
(:mod:`corl.trajectory.solver.sqp`, Newton-KKT steps on a banded Hessian, iterations independent
of the number of knots) for a problem with a banded affine cost and equalities under
``method="sqp"`` (the default); the augmented Lagrangian (:mod:`corl.trajectory.solver.al`) for
every other problem, and from the point where SQP has no step.

Alg. 1, step 2 maps a new theta to the closest trajectory (Eq. 18)::

    w^(i+1) = argmin_w ||L (w - w*)||^2   s.t.  h(w) = 0.

:func:`corl.realise.realise` is Eq. 18 in public; :func:`project` is the machinery it calls: SQP
on a structured problem, the manifold walk of :mod:`corl.trajectory.solver.manifold` (fast where
the augmented Lagrangian is only linear: large multipliers, since its Gauss-Newton Hessian drops
``lam^T d2h``), :func:`solve` as the fallback.

The learner calls :func:`solve` hundreds of times per run on 2-D problems, so the hot path avoids
repeated validation and numpy calls on tiny arrays (see :mod:`corl.trajectory.solver.model`).

Glossary
--------
w          : decision variables (trajectory parameters), (n,)
r, h       : cost residuals (p,) and equality constraints (q,); h(w) stands for h(w, theta)
lam, mu    : multipliers of h (q,) and the augmented Lagrangian's penalty weight
L, w*      : the metric of Eq. 18 (rows, n) (identity by default) and the point projected (n,)
center, radius : the trust-region ball ||w - center|| <= radius (eps_max of Eq. 8)
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

import numpy as np
import scipy.sparse as sp

from corl.errors import InputError
from corl.numerics import as_vector
from corl.trajectory.solver.al import augmented_lagrangian
from corl.trajectory.solver.manifold import project_on_manifold
from corl.trajectory.solver.model import Iterate, checked_pair, max_abs, non_finite_error, sumsq
from corl.trajectory.solver.problem import (
    FunctionProblem,
    IterationRecord,
    Jacobian,
    LeastSquaresProblem,
    SolveResult,
    SolverConfig,
    SolverMethod,
)
from corl.trajectory.solver.sqp import sqp, sqp_applies
from corl.trajectory.solver.state import SolveState

__all__ = ["solve", "project"]

_MANIFOLD_BUDGET = 60  # evaluations the manifold projection may use before project falls back on solve


# ---------------------------------------------------------------------------------------------
# Eq. 18 as a least-squares problem (the fallback of project)
# ---------------------------------------------------------------------------------------------
class _ProjectionProblem:
    """Eq. 18 as a least-squares problem: ``r = w - w*`` with Jacobian I, the given ``h``."""

    def __init__(self, equalities_fn: Callable, w_star: np.ndarray) -> None:
        self._equalities_fn = equalities_fn
        self._w_star = w_star
        self._identity: Jacobian | None = None

    def residuals(self, w: np.ndarray) -> tuple[np.ndarray, Jacobian]:
        if self._identity is None:  # sparse identity when h has a sparse Jacobian, dense otherwise
            n = w.shape[0]
            self._identity = sp.identity(n, format="csr") if sp.issparse(self.equalities(w)[1]) else np.eye(n)
        return w - self._w_star, self._identity

    def equalities(self, w: np.ndarray) -> tuple[np.ndarray, Jacobian]:
        return self._equalities_fn(w)


def _vector(x, n: int | None, name: str) -> np.ndarray:
    """:func:`corl.numerics.as_vector`, with a fast path for a finite float vector of the right length."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 1 and (n is None or x.shape[0] == n):
        # A finite sum of squares proves every entry finite (an overflow falls through to the full check).
        if math.isfinite(sumsq(x)):
            return x
    return as_vector(x, n, name=name)


def _prepare_ball(w: np.ndarray, w_init, center, radius) -> tuple[np.ndarray, np.ndarray | None, float]:
    """Validate the trust region and move ``w`` (a copy of ``w_init``) into it.

    Returns (w, center or None, radius).
    """
    try:
        radius = float(radius)
    except (TypeError, ValueError):
        raise InputError(f"radius must be a positive number or inf, got {radius!r}") from None
    if not radius > 0:  # also catches NaN
        raise InputError(f"radius must be positive (eps_max of Eq. 8), got {radius!r}")
    if radius == math.inf:
        return w, None, radius
    if center is None or center is w_init:  # Alg. 1, step 1: the ball around the start
        return w, w, radius  # (neither array is ever changed in place)
    center = _vector(center, w.shape[0], "center")
    offset = w - center
    dist = math.sqrt(np.dot(offset, offset))
    if dist > radius:  # start outside the ball: use its closest point in the ball
        w = center + (w - center) * (radius / dist)
    return w, center, radius


def solve(
    problem: LeastSquaresProblem,
    w_init,
    *,
    center=None,
    radius: float = math.inf,
    config: SolverConfig = SolverConfig(),
) -> SolveResult:
    """Solve ``min_w r(w)^T r(w)  s.t.  h(w) = 0,  ||w - center|| <= radius`` (Eq. 8).

    Parameters
    ----------
    problem : a :class:`LeastSquaresProblem` (use :class:`FunctionProblem` for two callables).
    w_init : (n,) start. When it lies outside the ball it is first moved to the ball's closest point.
    center : (n,) center of the trust region; default ``w_init`` (Alg. 1, step 1: ``w^(i)``).
        Ignored when ``radius`` is ``inf``.
    radius : trust-region radius ``eps_max``; ``inf`` (default) for none.
    config : tolerances and budgets, see :class:`SolverConfig`.

    Returns
    -------
    SolveResult
        ``converged`` is False (with the reason in ``status``) when the constraints could not be
        satisfied - inconsistent, or out of reach inside the ball - or a budget ran out. Every
        iterate, and the result, satisfies ``||w - center|| <= radius`` up to rounding.

    Raises
    ------
    InputError
        Bad shapes of ``w_init``, ``center``, or of what the problem returns; a bad radius.
    NumericalError
        The problem returned NaN or inf.
    """
    if type(config) is not SolverConfig and not isinstance(config, SolverConfig):
        raise InputError(f"config must be a SolverConfig, got {type(config).__name__}")
    w = _vector(w_init, None, "w_init").copy()
    if w.shape[0] == 0:
        raise InputError("w_init is empty; the solver needs at least one parameter")
    w, center, radius = _prepare_ball(w, w_init, center, radius)
    state = SolveState(problem, config, center, radius)
    pt = state.evaluate(w)
    state.record(pt, 0.0, 0.0, 0.0)
    handover = ""
    if sqp_applies(pt, config):  # banded affine cost with equalities (B-spline trajectories)
        pt, lam, converged, status = sqp(state, pt)
        if lam is not None:
            return _result(pt, state, lam, 0.0, converged, status)
        handover = f" (after {state.iterations} SQP iterations, which stopped: {status})"
    pt, lam, mu, converged, status = augmented_lagrangian(state, pt)
    return _result(pt, state, lam, mu, converged, status + handover)


def _result(pt: Iterate, state: SolveState, lam: np.ndarray, mu: float, converged: bool, status: str) -> SolveResult:
    active = state.on_boundary(pt.w)
    return SolveResult(
        w=pt.w,
        cost=pt.rr,
        constraint_error=pt.err,
        multipliers=lam + (2.0 * mu) * pt.h,  # first-order estimate: grad J + Jh^T (lam + 2 mu h) = 0
        converged=converged,
        status=status,
        iterations=state.iterations,
        outer_iterations=state.outer + 1,
        evaluations=state.evaluations,
        trust_region_active=active,
        history=tuple(state.history),
    )


def project(equalities, w_star, *, w_init=None, metric=None, config: SolverConfig = SolverConfig()) -> SolveResult:
    """Closest point to ``w_star`` that satisfies the constraints: the machinery of Eq. 18.

    ``argmin_w ||L (w - w*)||^2  s.t.  h(w) = 0`` with ``L`` the ``metric`` or the identity. The
    public Eq. 18 for a task and a theta is :func:`corl.realise.realise`, which calls this; use
    this function directly only for an ``h`` that belongs to no task (a demonstration's fit, a
    re-timed path, tests).

    * A structured problem (one with ``distance_problem(w_star, metric)``, e.g. a
      :class:`~corl.trajectory.features.TrajectoryProblem`) under ``method="sqp"`` is solved by
      :func:`solve` on its banded SQP path (the distance is a linear cost).
    * Otherwise, in the identity metric, it follows the manifold ``h = 0``
      (:mod:`corl.trajectory.solver.manifold`: min-norm restoration and tangent steps, superlinear
      where the augmented Lagrangian is only linear).
    * Where those give up - a singular ``dh/dw``, a failed restoration, no descent - or with a
      metric and no structure, :func:`solve` on the residuals ``L (w - w*)`` from the same start.

    Parameters
    ----------
    equalities : callable ``w (n,) -> (h (q,), dh/dw (q, n))``, or an object with an
        ``equalities`` method (a :class:`LeastSquaresProblem`).
    w_star : (n,) point to project.
    w_init : (n,) start; default ``w_star``.
    metric : sparse or dense ``L`` (rows, n), or None for the Euclidean distance.
    config : see :class:`SolverConfig`.

    Returns
    -------
    SolveResult
        ``cost`` is ``||L (w - w*)||^2``. In the fallback, the residual Jacobian is a sparse
        identity when ``dh/dw`` is sparse, a dense one otherwise.
    """
    if type(config) is not SolverConfig and not isinstance(config, SolverConfig):
        raise InputError(f"config must be a SolverConfig, got {type(config).__name__}")
    w_star = as_vector(w_star, name="w_star")
    fn = getattr(equalities, "equalities", equalities)
    if not callable(fn):
        raise InputError(f"equalities must be a callable w -> (h, dh/dw) or a problem, got {equalities!r}")
    start = w_star if w_init is None else as_vector(w_init, w_star.shape[0], name="w_init")
    n = w_star.shape[0]
    spent = 0  # evaluations of attempts that gave up
    structured = getattr(equalities, "distance_problem", None)
    if structured is not None and config.method is SolverMethod.SQP:
        result = solve(structured(w_star, metric), start, config=config)
        if result.converged:
            return result
        spent = result.evaluations
    if metric is not None:
        L = metric
        result = solve(FunctionProblem(lambda w: (L @ (w - w_star), L), fn), start, config=config)
        return replace(result, evaluations=result.evaluations + spent)
    calls = [0]

    def evaluate(w: np.ndarray) -> tuple[np.ndarray, Jacobian, float]:
        calls[0] += 1
        h, Jh = checked_pair(fn(w), n, "equalities", "dh/dw")
        if not math.isfinite(sumsq(h)):
            raise non_finite_error("equalities", w, "check the constraint h(w, theta) and its domain")
        return h, Jh, max_abs(h)

    found = project_on_manifold(
        evaluate,
        w_star,
        start.copy(),
        tol_constraint=config.tol_constraint,
        tol_step=config.tol_step,
        max_evaluations=min(config.max_iterations, _MANIFOLD_BUDGET),
    )
    if found is None or found.error > config.tol_constraint:
        result = solve(_ProjectionProblem(fn, w_star), start, config=config)
        return replace(result, evaluations=result.evaluations + calls[0] + spent)  # count the attempts too
    history = tuple(IterationRecord(k - 1, 0, cost, err, step, 0.0, 0.0, w) for k, cost, err, step, w in found.history)
    return SolveResult(
        w=found.w,
        cost=found.cost,
        constraint_error=found.error,
        multipliers=found.multipliers,
        converged=True,
        status=(
            f"converged: the tangent step along h(w) = 0 is below tol_step and max|h| = {found.error:.2e} "
            f"<= tol_constraint = {config.tol_constraint:g}"
        ),
        iterations=found.evaluations - 1,
        outer_iterations=1,
        evaluations=found.evaluations,
        trust_region_active=False,
        history=history,
    )
