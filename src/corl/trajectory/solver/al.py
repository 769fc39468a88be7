"""The augmented Lagrangian strategy of :func:`~corl.trajectory.solver.solve` (Eq. 8, any problem).

An outer loop on ``h`` (Nocedal & Wright, Numerical Optimization, Framework 17.3; Toussaint's
KOMO [27]) around Levenberg-Marquardt damped Gauss-Newton steps on

    L_A(w) = r^T r + lam^T h + mu h^T h,

each of which minimises the quadratic model exactly inside the trust-region ball (More &
Sorensen's Newton iteration on the ball multiplier, :func:`corl.trajectory.solver.linalg.model_step`),
so every iterate satisfies the trust-region constraint. When it stalls a hair away from ``h = 0``,
minimum-norm Newton steps on ``h`` alone restore feasibility (:func:`restore`).

It reads and writes the shared :class:`~corl.trajectory.solver.state.SolveState` (ball, damping,
counters, history) and the :class:`~corl.trajectory.solver.model.Iterate` of the current point, as
SQP does (:mod:`corl.trajectory.solver.sqp`), which hands over to it where it has no step.

Glossary
--------
w          : decision variables (n,)
r, h       : cost residuals (p,) and equality constraints (q,), J = r^T r (Eq. 7)
lam, mu    : multiplier estimate (q,) and penalty weight of L_A
g, H       : gradient (n,) and Gauss-Newton Hessian (n, n) of L_A
damping    : Levenberg-Marquardt multiple of the identity added to H
u, z       : offsets from the ball's center of the current point and of the trial point, (n,)
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from corl.errors import NumericalError
from corl.trajectory.solver.linalg import model_step
from corl.trajectory.solver.model import (
    Iterate,
    check_gradient,
    compute_grams,
    gauss_newton,
    lagrangian,
    max_diagonal,
    sumsq,
)
from corl.trajectory.solver.state import SolveState

__all__ = ["InnerStatus", "minimize_lagrangian", "augmented_lagrangian", "restore"]

_ACCEPT_RATIO = 1e-4  # accept a step when the actual decrease of L_A is >= this x the predicted one
_STUCK_LIMIT = 2  # outer iterations without progress before declaring the constraints unsatisfiable
_RESTORE_REACH = 10.0  # restoration is tried only at max|h| <= this x tol_constraint (see restore)
_RESTORE_STEPS = 3
_INDEFINITE_DAMPING = 1e-6  # first damping, relative to maxdiag(H), when the curvature makes H indefinite


class InnerStatus:
    """How an inner solve (:func:`minimize_lagrangian`) ended."""

    CONVERGED = "converged"  # the step is below tol_step, or no step decreases the model
    APPROXIMATE = "approximate"  # an inexact solve for a multiplier update ended (still infeasible)
    STALLED = "stalled"  # the damping reached its ceiling: no step decreases L_A
    BUDGET = "budget"  # max_iterations used


_CONVERGED, _APPROXIMATE, _STALLED, _BUDGET = (InnerStatus.CONVERGED, InnerStatus.APPROXIMATE, InnerStatus.STALLED,
                                               InnerStatus.BUDGET)


def minimize_lagrangian(state: SolveState, pt: Iterate, lam: np.ndarray, mu: float,
                        rtol: float) -> tuple[Iterate, str]:
    """Inner loop: damped Gauss-Newton on L_A inside the ball, from ``pt`` until the step is small.

    The step is small when ``||d|| <= tol_step (1 + ||w||)``, or, with ``rtol > 0`` (an inexact
    solve for a multiplier update), when ``||d|| <= rtol`` times the first accepted step of this
    call. An inexact solve that ends feasible (``max|h| <= tol_constraint``) goes on as a tight
    one with the same lam and mu (the polish before stopping), so it never returns
    ``_APPROXIMATE`` at a feasible point.
    """
    cfg = state.config
    first = 0.0  # norm of the first accepted step of this call
    L, _ = lagrangian(pt, lam, mu)
    g, H = gauss_newton(pt, lam, mu)
    if state.damping == 0.0:
        state.set_damping_scale(H)
    # lam or mu changed, so damping raised for the previous L_A need not apply: start low again.
    state.damping = min(state.damping, state.damping_start)
    state.growth = 2.0
    while True:
        if state.iterations >= cfg.max_iterations:
            return pt, _BUDGET
        u = None if state.center is None else pt.w - state.center
        try:
            d, z, dn, predicted = model_step(H, g, state.damping, u, state.radius)  # predicted: decrease of L_A
        except NumericalError:
            if pt.curvature is None:
                raise
            # Constraint curvature made H + damping I indefinite: raise the damping (inertia correction).
            state.damping = max(state.damping * state.growth, _INDEFINITE_DAMPING * state.scale)
            state.growth *= 2.0
            if state.damping > state.damping_ceiling:
                return pt, _STALLED
            continue
        if not math.isfinite(dn):
            check_gradient(g)  # a non-finite step comes from g or from H
            raise NumericalError(
                "the Gauss-Newton step is NaN or inf; the Jacobians are probably non-finite or wildly scaled"
            )
        if dn <= cfg.tol_step * (1.0 + math.sqrt(sumsq(pt.w))) or predicted <= 0.0:
            return pt, _CONVERGED
        if dn <= rtol * first:
            if pt.err > cfg.tol_constraint:
                return pt, _APPROXIMATE
            # Feasible: polish with the same lam, mu (tight solve, damping reset as for a new L_A).
            rtol, state.growth = 0.0, 2.0
            if state.damping > state.damping_start:
                state.damping = state.damping_start
                continue  # recompute the step with the lower damping
        state.iterations += 1
        trial = state.evaluate(state.new_point(pt.w, d, z))
        L_trial, noise = lagrangian(trial, lam, mu)
        rho = (L - L_trial) / predicted
        # Near the solution the predicted decrease drops below the rounding noise of L_A; the
        # step, computed from derivatives, is still good, so accept it unless L_A clearly rose.
        at_noise_level = predicted <= noise and L_trial <= L + noise
        if rho > _ACCEPT_RATIO or at_noise_level:  # accept; Nielsen's damping update
            state.record(trial, dn, state.damping, mu)
            rho = 1.0 if at_noise_level else rho
            state.damping = max(state.damping * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), state.damping_floor)
            state.growth = 2.0
            first = first or dn
            pt, L = trial, L_trial
            g, H = gauss_newton(pt, lam, mu)
        else:  # reject: raise the damping
            state.damping *= state.growth
            state.growth *= 2.0
            if state.damping > state.damping_ceiling:
                return pt, _STALLED


def augmented_lagrangian(state: SolveState, pt: Iterate) -> tuple[Iterate, np.ndarray, float, bool, str]:
    """Outer loop (N&W Framework 17.3): minimise L_A over w, then lam <- lam + 2 mu h.

    Returns the final point, multipliers ``lam`` (q,), penalty ``mu``, converged flag and status.
    """
    config = state.config
    q = pt.h.shape[0]
    lam = np.zeros(q)
    _, JrJr, JhJh = pt.grams or compute_grams(pt)
    c_cost, c_con = max_diagonal(JrJr), (max_diagonal(JhJh) if q else 0.0)  # maxdiag(Jr^T Jr), maxdiag(Jh^T Jh)
    mu0 = mu = config.mu_init * (c_cost / c_con if c_cost > 0 and c_con > 0 else 1.0)
    # Inexact inner solves while the multipliers are still moving; a tight one before stopping.
    rtol = config.inner_rtol if q else 0.0
    previous_w, previous_violation = pt.w, math.sqrt(pt.hh)
    stuck = 0
    for outer in range(config.max_outer_iterations):
        state.outer = outer
        pt, inner = minimize_lagrangian(state, pt, lam, mu, rtol)  # polishes when it ends feasible
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
        moved = math.sqrt(sumsq(pt.w - previous_w))
        still = moved <= config.tol_step * (1.0 + math.sqrt(sumsq(pt.w)))
        stuck = stuck + 1 if still and violation >= 0.999 * previous_violation else 0
        shrunk = violation <= config.violation_decrease * previous_violation
        if stuck >= _STUCK_LIMIT or (not shrunk and mu * config.mu_growth > config.mu_max * mu0):
            restored = restore(state, pt)
            if restored is not None:  # the last digits of h were out of L_A's reach, not out of the ball's
                return restored, lam, mu, True, (
                    f"converged: w stopped moving at max|h| = {error:.2e}, and minimum-norm Newton steps on h "
                    f"brought it to {restored.err:.2e} <= tol_constraint = {config.tol_constraint:g}"
                )
            return pt, lam, mu, False, _infeasible_status(pt, state, error, mu, stuck >= _STUCK_LIMIT)
        # Multiplier update: lam <- lam + 2 mu h; grow mu when ||h|| did not shrink enough.
        lam = lam + (2.0 * mu) * pt.h
        if not shrunk:
            mu *= config.mu_growth
        previous_w, previous_violation = pt.w, violation
    return pt, lam, mu, False, (
        f"not converged: max_outer_iterations = {config.max_outer_iterations} multiplier updates used, "
        f"max|h| = {pt.err:.2e}; raise max_outer_iterations or mu_growth"
    )


def restore(state: SolveState, pt: Iterate) -> Iterate | None:
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
    tol = state.config.tol_constraint
    if pt.Jh is None or not pt.err <= _RESTORE_REACH * tol:
        return None
    best = pt
    for _ in range(_RESTORE_STEPS):
        Jh = best.Jh.toarray() if sp.issparse(best.Jh) else np.asarray(best.Jh, dtype=float)
        rhs = -best.h
        if state.center is not None:
            u = best.w - state.center
            if math.sqrt(sumsq(u)) >= state.radius * (1.0 - 1e-9):  # active ball: stay tangent to it
                Jh, rhs = np.vstack([Jh, u]), np.append(rhs, 0.0)
        d = np.linalg.lstsq(Jh, rhs, rcond=None)[0]
        w = best.w + d
        if state.center is not None:
            offset = w - state.center
            dist = math.sqrt(sumsq(offset))
            if dist > state.radius:
                w = state.center + offset * (state.radius / dist)
        trial = state.evaluate(w)
        if not trial.err < best.err:
            break
        best = trial
        state.record(best, math.sqrt(sumsq(d)), 0.0, 0.0)
        if best.err <= tol:
            return best
    return None


def _infeasible_status(pt: Iterate, state: SolveState, error: float, mu: float, stuck: bool) -> str:
    where = f" inside the trust region of radius {state.radius:g} (active)" if state.on_boundary(pt.w) else ""
    why = (
        "w stopped moving (a local minimum of ||h||^2, or a point where dh/dw degenerates)"
        if stuck
        else f"the penalty reached mu = {mu:.3g}"
    )
    return (
        f"not converged: the equality constraints cannot be satisfied{where}: max|h| = {error:.2e} > "
        f"tol_constraint = {state.config.tol_constraint:g} and {why}; check that the constraints are "
        "consistent and reachable from the start (a larger radius or a start closer to h(w) = 0)"
    )
