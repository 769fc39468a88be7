"""Constrained Gauss-Newton with augmented Lagrangian and a trust region (Eq. 8, Eq. 18).

Alg. 1, step 1 improves the trajectory parameters on the analytic cost while the constraint h
keeps theta fixed and a ball limits the change (Eq. 8)::

    w^(i+1) = argmin_w J(w)   s.t.  h(w) = 0,  ||w - w^(i)|| <= eps_max,    J(w) = r(w)^T r(w)  (Eq. 7)

Alg. 1, step 2 maps a new theta to the closest trajectory (Eq. 18)::

    w^(i+1) = argmin_w ||w - w*||^2   s.t.  h(w) = 0.

Eq. 8 is solved by :func:`solve`: an augmented Lagrangian outer loop on ``h`` (Nocedal & Wright,
Numerical Optimization, Framework 17.3; Toussaint's KOMO [27]) around Levenberg-Marquardt damped
Gauss-Newton steps, each of which minimises the quadratic model exactly inside the ball (More &
Sorensen's Newton iteration on the ball multiplier, :mod:`corl.trajectory.linalg`), so every
iterate satisfies the trust-region constraint. The model itself (evaluation, gradient, Gauss-Newton
Hessian) lives in :mod:`corl.trajectory.model`. With ``SolverConfig(method="sqp")`` (the
``trajectory`` preset), a problem with a banded affine cost is solved by SQP instead
(:mod:`corl.trajectory.sqp`: Newton-KKT steps, iterations independent of the number of knots),
which hands over to the augmented Lagrangian where it has no step.

Eq. 18 is solved by :func:`project`: restoration and tangent steps along ``h = 0``
(:mod:`corl.trajectory.projection`), which converge fast where the augmented Lagrangian is only
linear (large multipliers, since its Gauss-Newton Hessian drops ``lam^T d2h``), with :func:`solve`
as the fallback.

The problem, configuration and result types (:class:`LeastSquaresProblem`, :class:`SolverConfig`,
:class:`SolveResult`, ...) live in :mod:`corl.trajectory.problem_types` and are re-exported here.

The learner calls :func:`solve` hundreds of times per run on 2-D problems, so the hot path avoids
repeated validation and numpy calls on tiny arrays (see :mod:`corl.trajectory.model`).

Glossary
--------
w          : decision variables (trajectory parameters), (n,)
r, Jr      : cost residuals (p,) and their Jacobian dr/dw (p, n); J = r^T r (Eq. 7)
h, Jh      : equality constraints (q,) and their Jacobian dh/dw (q, n); h(w) stands for h(w, theta)
lam        : Lagrange multiplier estimate of h, (q,)
mu         : penalty weight of the augmented Lagrangian
L_A        : augmented Lagrangian  r^T r + lam^T h + mu h^T h
g, H       : gradient (n,) and Gauss-Newton Hessian (n, n) of L_A
damping    : Levenberg-Marquardt multiple of the identity added to H
center, radius : the trust-region ball ||w - center|| <= radius (eps_max of Eq. 8)
u, z       : offsets from the center of the current point and of the trial point, (n,)
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

import numpy as np
import scipy.sparse as sp

from corl.errors import InputError, NumericalError
from corl.numerics import as_vector
from corl.trajectory.linalg import model_step
from corl.trajectory.model import (
    _checked_pair,
    _evaluate,
    _gauss_newton,
    _grams,
    _lagrangian,
    _max_abs,
    _max_diagonal,
    _non_finite,
    _Point,
    _sumsq,
)
from corl.trajectory.problem_types import (  # re-exported: corl.trajectory.solver stays the public entry
    _DAMPING_FLOOR,
    FunctionProblem,
    IterationRecord,
    Jacobian,
    LeastSquaresProblem,
    SolveResult,
    SolverConfig,
    SolverMethod,
)
from corl.trajectory.projection import project_on_manifold
from corl.trajectory.sqp import sqp, sqp_applies

__all__ = [
    "LeastSquaresProblem",
    "FunctionProblem",
    "SolverConfig",
    "SolverMethod",
    "IterationRecord",
    "SolveResult",
    "solve",
    "project",
]

_ACCEPT_RATIO = 1e-4  # accept a step when the actual decrease of L_A is >= this x the predicted one
_STUCK_LIMIT = 2  # outer iterations without progress before declaring the constraints unsatisfiable
_RESTORE_REACH = 10.0  # restoration is tried only at max|h| <= this x tol_constraint (see _restore)
_RESTORE_STEPS = 3
_INDEFINITE_DAMPING = 1e-6  # first damping, relative to maxdiag(H), when the curvature makes H indefinite
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


# ---------------------------------------------------------------------------------------------
# The solver
# ---------------------------------------------------------------------------------------------
_CONVERGED, _APPROXIMATE, _STALLED, _BUDGET = "converged", "approximate", "stalled", "budget"


class _Run:
    """Mutable state of one :func:`solve` call: the ball, damping, counters and history."""

    def __init__(self, problem, config: SolverConfig, center, radius: float) -> None:
        self.problem = problem
        self.config = config
        self.center = center  # None without trust region
        self.radius = radius
        self.damping = 0.0  # set from the first Hessian
        self.damping_start = self.damping_floor = 0.0
        self.scale = 1.0  # largest diagonal entry of the first H
        self.damping_ceiling = 0.0
        self.growth = 2.0  # Nielsen's factor for consecutive rejections
        self.iterations = 0
        self.evaluations = 0
        self.outer = 0
        self.history: list[IterationRecord] = []
        # center + z rounds by at most 1.12e-16 (||center|| + radius) in norm; recheck the distance
        # of new points only when that could exceed 1e-12 radius.
        self.recheck = center is not None and 2.3e-16 * (math.sqrt(_sumsq(center)) + radius) > 1e-12 * radius

    def evaluate(self, w: np.ndarray) -> _Point:
        self.evaluations += 1
        return _evaluate(self.problem, w)

    def record(self, pt: _Point, step_norm: float, damping: float, mu: float) -> None:
        self.history.append(
            IterationRecord(self.iterations, self.outer, pt.rr, pt.err, step_norm, damping, mu, pt.w)
        )

    def set_damping_scale(self, H: Jacobian) -> None:
        scale = _max_diagonal(H)
        scale = scale if scale > 0 and math.isfinite(scale) else 1.0
        self.scale = scale
        self.damping = self.damping_start = self.config.damping_init * scale
        self.damping_floor = _DAMPING_FLOOR * scale
        self.damping_ceiling = self.config.damping_max * scale

    def new_point(self, w: np.ndarray, d: np.ndarray, z: np.ndarray | None) -> np.ndarray:
        """``w + d``, placed exactly on the ball when the step ended on its boundary."""
        if z is None:
            return w + d
        w_new = self.center + z
        if not self.recheck:
            return w_new
        offset = w_new - self.center
        dist = math.sqrt(_sumsq(offset))
        if dist > self.radius:  # rounding in center + z
            w_new = self.center + offset * (self.radius / dist)
        return w_new

    def minimize_lagrangian(self, pt: _Point, lam: np.ndarray, mu: float, rtol: float) -> tuple[_Point, str]:
        """Inner loop: damped Gauss-Newton on L_A inside the ball, from ``pt`` until the step is small.

        The step is small when ``||d|| <= tol_step (1 + ||w||)``, or, with ``rtol > 0`` (an inexact
        solve for a multiplier update), when ``||d|| <= rtol`` times the first accepted step of this
        call. An inexact solve that ends feasible (``max|h| <= tol_constraint``) goes on as a tight
        one with the same lam and mu (the polish before stopping), so it never returns
        ``_APPROXIMATE`` at a feasible point.
        """
        cfg = self.config
        first = 0.0  # norm of the first accepted step of this call
        L, _ = _lagrangian(pt, lam, mu)
        g, H = _gauss_newton(pt, lam, mu)
        if self.damping == 0.0:
            self.set_damping_scale(H)
        # lam or mu changed, so damping raised for the previous L_A need not apply: start low again.
        self.damping = min(self.damping, self.damping_start)
        self.growth = 2.0
        while True:
            if self.iterations >= cfg.max_iterations:
                return pt, _BUDGET
            u = None if self.center is None else pt.w - self.center
            try:
                d, z, dn, predicted = model_step(H, g, self.damping, u, self.radius)  # predicted: decrease of L_A
            except NumericalError:
                if pt.curvature is None:
                    raise
                # Constraint curvature made H + damping I indefinite: raise the damping (inertia correction).
                self.damping = max(self.damping * self.growth, _INDEFINITE_DAMPING * self.scale)
                self.growth *= 2.0
                if self.damping > self.damping_ceiling:
                    return pt, _STALLED
                continue
            if not math.isfinite(dn):
                _check_gradient(g)  # a non-finite step comes from g or from H
                raise NumericalError(
                    "the Gauss-Newton step is NaN or inf; the Jacobians are probably non-finite or wildly scaled"
                )
            if dn <= cfg.tol_step * (1.0 + math.sqrt(_sumsq(pt.w))) or predicted <= 0.0:
                return pt, _CONVERGED
            if dn <= rtol * first:
                if pt.err > cfg.tol_constraint:
                    return pt, _APPROXIMATE
                # Feasible: polish with the same lam, mu (tight solve, damping reset as for a new L_A).
                rtol, self.growth = 0.0, 2.0
                if self.damping > self.damping_start:
                    self.damping = self.damping_start
                    continue  # recompute the step with the lower damping
            self.iterations += 1
            trial = self.evaluate(self.new_point(pt.w, d, z))
            L_trial, noise = _lagrangian(trial, lam, mu)
            rho = (L - L_trial) / predicted
            # Near the solution the predicted decrease drops below the rounding noise of L_A; the
            # step, computed from derivatives, is still good, so accept it unless L_A clearly rose.
            at_noise_level = predicted <= noise and L_trial <= L + noise
            if rho > _ACCEPT_RATIO or at_noise_level:  # accept; Nielsen's damping update
                self.record(trial, dn, self.damping, mu)
                rho = 1.0 if at_noise_level else rho
                self.damping = max(self.damping * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), self.damping_floor)
                self.growth = 2.0
                first = first or dn
                pt, L = trial, L_trial
                g, H = _gauss_newton(pt, lam, mu)
            else:  # reject: raise the damping
                self.damping *= self.growth
                self.growth *= 2.0
                if self.damping > self.damping_ceiling:
                    return pt, _STALLED


def _vector(x, n: int | None, name: str) -> np.ndarray:
    """:func:`corl.numerics.as_vector`, with a fast path for a finite float vector of the right length."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.ndim == 1 and (n is None or x.shape[0] == n):
        # A finite sum of squares proves every entry finite (an overflow falls through to the full check).
        if math.isfinite(_sumsq(x)):
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
    run = _Run(problem, config, center, radius)
    pt = run.evaluate(w)
    run.record(pt, 0.0, 0.0, 0.0)
    handover = ""
    if sqp_applies(pt, config):  # banded affine cost with equalities (B-spline trajectories)
        pt, lam, converged, status = sqp(run, pt)
        if lam is not None:
            return _result(pt, run, lam, 0.0, converged, status)
        handover = f" (after {run.iterations} SQP iterations, which stopped: {status})"
    pt, lam, mu, converged, status = _augmented_lagrangian(run, pt)
    return _result(pt, run, lam, mu, converged, status + handover)


def _augmented_lagrangian(run: _Run, pt: _Point) -> tuple[_Point, np.ndarray, float, bool, str]:
    """Outer loop (N&W Framework 17.3): minimise L_A over w, then lam <- lam + 2 mu h.

    Returns the final point, multipliers ``lam`` (q,), penalty ``mu``, converged flag and status.
    """
    config = run.config
    q = pt.h.shape[0]
    lam = np.zeros(q)
    _, JrJr, JhJh = pt.grams or _grams(pt)
    c_cost, c_con = _max_diagonal(JrJr), (_max_diagonal(JhJh) if q else 0.0)  # maxdiag(Jr^T Jr), maxdiag(Jh^T Jh)
    mu0 = mu = config.mu_init * (c_cost / c_con if c_cost > 0 and c_con > 0 else 1.0)
    # Inexact inner solves while the multipliers are still moving; a tight one before stopping.
    rtol = config.inner_rtol if q else 0.0
    previous_w, previous_violation = pt.w, math.sqrt(pt.hh)
    stuck = 0
    for outer in range(config.max_outer_iterations):
        run.outer = outer
        pt, inner = run.minimize_lagrangian(pt, lam, mu, rtol)  # polishes when it ends feasible
        error = pt.err
        if inner == _BUDGET:
            return pt, lam, mu, False, (
                f"not converged: max_iterations = {config.max_iterations} Gauss-Newton iterations used, "
                f"max|h| = {error:.2e}; raise max_iterations or loosen tol_step / tol_constraint"
            )
        if error <= config.tol_constraint:
            how = "the step is below tol_step" if inner == _CONVERGED else "no step decreases L_A any more"
            return pt, lam, mu, True, (
                f"converged: {how} and max|h| = {error:.2e} <= tol_constraint = {config.tol_constraint:g}"
            )
        violation = math.sqrt(pt.hh)
        # No progress: w stopped moving and ||h|| stopped shrinking (a local minimum of ||h||^2).
        moved = math.sqrt(_sumsq(pt.w - previous_w))
        still = moved <= config.tol_step * (1.0 + math.sqrt(_sumsq(pt.w)))
        stuck = stuck + 1 if still and violation >= 0.999 * previous_violation else 0
        shrunk = violation <= config.violation_decrease * previous_violation
        if stuck >= _STUCK_LIMIT or (not shrunk and mu * config.mu_growth > config.mu_max * mu0):
            restored = _restore(run, pt)
            if restored is not None:  # the last digits of h were out of L_A's reach, not out of the ball's
                return restored, lam, mu, True, (
                    f"converged: w stopped moving at max|h| = {error:.2e}, and minimum-norm Newton steps on h "
                    f"brought it to {restored.err:.2e} <= tol_constraint = {config.tol_constraint:g}"
                )
            return pt, lam, mu, False, _infeasible_status(pt, run, error, mu, stuck >= _STUCK_LIMIT)
        # Multiplier update: lam <- lam + 2 mu h; grow mu when ||h|| did not shrink enough.
        lam = lam + (2.0 * mu) * pt.h
        if not shrunk:
            mu *= config.mu_growth
        previous_w, previous_violation = pt.w, violation
    return pt, lam, mu, False, (
        f"not converged: max_outer_iterations = {config.max_outer_iterations} multiplier updates used, "
        f"max|h| = {pt.err:.2e}; raise max_outer_iterations or mu_growth"
    )


def _restore(run: _Run, pt: _Point) -> _Point | None:
    """Feasibility restoration when the augmented Lagrangian stalls close to ``h = 0``.

    Near a solution on the ball's boundary the decrease of L_A that the last digits of ``h`` could
    buy is below L_A's own rounding noise, so w stops moving at a small violation whose size
    depends on how the machine's BLAS rounds (3e-10 with OpenBLAS's Haswell kernel, 4e-11 with
    SkylakeX, on the same problem). Up to ``_RESTORE_STEPS`` minimum-norm Newton steps on ``h``
    alone, ``d = -A^+ [h; 0]`` with ``A = [dh/dw; u^T]`` (``u^T d = 0`` keeps the step tangent to
    the ball when it is active; its second-order drift ``||d||^2 / (2 radius)`` is put back by
    placing the point on the ball), then bring ``max|h|`` below ``tol_constraint``.

    Returns the restored point, or None when the violation is not small (over
    ``_RESTORE_REACH`` x tol_constraint: a genuinely unsatisfiable constraint), ``dh/dw`` is only
    held as its Gram matrix, or the steps do not reach the tolerance.
    """
    tol = run.config.tol_constraint
    if pt.Jh is None or not pt.err <= _RESTORE_REACH * tol:
        return None
    best = pt
    for _ in range(_RESTORE_STEPS):
        Jh = best.Jh.toarray() if sp.issparse(best.Jh) else np.asarray(best.Jh, dtype=float)
        rhs = -best.h
        if run.center is not None:
            u = best.w - run.center
            if math.sqrt(_sumsq(u)) >= run.radius * (1.0 - 1e-9):  # active ball: stay tangent to it
                Jh, rhs = np.vstack([Jh, u]), np.append(rhs, 0.0)
        d = np.linalg.lstsq(Jh, rhs, rcond=None)[0]
        w = best.w + d
        if run.center is not None:
            offset = w - run.center
            dist = math.sqrt(_sumsq(offset))
            if dist > run.radius:
                w = run.center + offset * (run.radius / dist)
        trial = run.evaluate(w)
        if not trial.err < best.err:
            break
        best = trial
        run.record(best, math.sqrt(_sumsq(d)), 0.0, 0.0)
        if best.err <= tol:
            return best
    return None


def _infeasible_status(pt: _Point, run: _Run, error: float, mu: float, stuck: bool) -> str:
    where = ""
    if run.center is not None:
        offset = pt.w - run.center
        if math.sqrt(_sumsq(offset)) >= run.radius * (1 - 1e-9):
            where = f" inside the trust region of radius {run.radius:g} (active)"
    why = (
        "w stopped moving (a local minimum of ||h||^2, or a point where dh/dw degenerates)"
        if stuck
        else f"the penalty reached mu = {mu:.3g}"
    )
    return (
        f"not converged: the equality constraints cannot be satisfied{where}: max|h| = {error:.2e} > "
        f"tol_constraint = {run.config.tol_constraint:g} and {why}; check that the constraints are "
        "consistent and reachable from the start (a larger radius or a start closer to h(w) = 0)"
    )


def _result(pt: _Point, run: _Run, lam: np.ndarray, mu: float, converged: bool, status: str) -> SolveResult:
    active = False
    if run.center is not None:
        offset = pt.w - run.center
        active = math.sqrt(_sumsq(offset)) >= run.radius * (1 - 1e-9)
    return SolveResult(
        w=pt.w,
        cost=pt.rr,
        constraint_error=pt.err,
        multipliers=lam + (2.0 * mu) * pt.h,  # first-order estimate: grad J + Jh^T (lam + 2 mu h) = 0
        converged=converged,
        status=status,
        iterations=run.iterations,
        outer_iterations=run.outer + 1,
        evaluations=run.evaluations,
        trust_region_active=active,
        history=tuple(run.history),
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
      (:mod:`corl.trajectory.projection`: min-norm restoration and tangent steps, superlinear
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
        h, Jh = _checked_pair(fn(w), n, "equalities", "dh/dw")
        if not math.isfinite(_sumsq(h)):
            raise _non_finite("equalities", w, "check the constraint h(w, theta) and its domain")
        return h, Jh, _max_abs(h)

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
