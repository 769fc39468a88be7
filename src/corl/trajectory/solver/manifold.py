"""Closest feasible point (Eq. 18) by restoration and tangent steps along the constraint manifold.

Alg. 1, step 2 needs ``w = argmin ||w - w*||^2 s.t. h(w) = 0``. The augmented Lagrangian of
:func:`corl.trajectory.solver.solve` converges only linearly on it when the multiplier is large,
because its Gauss-Newton Hessian drops the constraint curvature ``lam^T d2h``. This module follows
the manifold ``h = 0`` instead (a feasible-path, Riemannian gradient method):

1. restoration: min-norm Gauss-Newton steps ``x <- x - Jh^T G^{-1} h`` (quadratic convergence
   onto ``h = 0``, with backtracking on ``||h||``);
2. tangent step: ``v = P (w* - x)``, the steepest descent of ``||x - w*||^2 / 2`` within the tangent
   space, taken with a Barzilai-Borwein length ``alpha`` (1 on a flat manifold, where one step is
   exact) and restored; accepted when ``||x - w*||^2`` decreases (Armijo), else ``alpha`` is halved.

It stops at a feasible point where ``||v|| <= tol_step (1 + ||x||)`` (a KKT point of Eq. 18), and
gives up (returns None) when the restoration fails, ``G`` is singular or the budget runs out; the
caller then falls back on the augmented Lagrangian. Only ``q x q`` matrices are formed: sparse
Jacobians with n in the thousands stay sparse.

Glossary
--------
w*      : point to project, (n,)
x       : current feasible iterate, (n,)
h, Jh   : constraints (q,) and their Jacobian dh/dw (q, n), ndarray or scipy.sparse
G       : normal matrix ``Jh Jh^T``, (q, q), dense
P       : projector onto the tangent space ``I - Jh^T G^{-1} Jh`` (never formed)
v       : tangent step ``P (w* - x)``, (n,)
alpha   : length of the tangent step
f       : ``||x - w*||^2``, the cost of Eq. 18
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from corl.trajectory.solver.linalg import factorize_spd

__all__ = ["ManifoldProjection", "project_on_manifold"]

_RESTORE_RTOL = 1e-3  # restore to max|h| <= this x tol_constraint (Newton: one step more is cheap)
_ARMIJO = 1e-4  # accept a tangent step when f decreases by >= this x its first-order prediction
_DEGENERATE = 1e-14  # G is singular when its smallest pivot^2 is below this x its largest diagonal
_NOISE = 8 * np.finfo(float).eps
_ALPHA_MIN, _ALPHA_MAX = 1e-3, 1e3  # Barzilai-Borwein safeguards
_MAX_HALVINGS = 12  # consecutive rejected tangent steps (or restoration backtracks) before giving up

Jacobian = Any  # np.ndarray or scipy.sparse matrix, (q, n)
Evaluate = Callable[[np.ndarray], "tuple[np.ndarray, Jacobian, float]"]  # x -> (h, Jh, max|h|)


class ManifoldProjection:
    """Outcome of :func:`project_on_manifold` (attributes as in the constructor).

    Attributes
    ----------
    w : (n,) the projection; ``h`` : (q,) the constraints there; ``error`` : ``max |h|``.
    cost : ``||w - w*||^2``.
    multipliers : (q,) ``nu`` with ``2 (w - w*) + Jh^T nu = 0`` in the least-squares sense.
    evaluations : calls of the constraint function.
    history : one ``(evaluations, cost, error, step_norm, w)`` per accepted point, the start first.
    """

    __slots__ = ("w", "h", "error", "cost", "multipliers", "evaluations", "history")

    def __init__(self, w, h, error, cost, multipliers, evaluations, history) -> None:
        self.w, self.h, self.error, self.cost = w, h, error, cost
        self.multipliers, self.evaluations, self.history = multipliers, evaluations, history


class _Normal:
    """``G = Jh Jh^T`` factorized at one point; maps between the normal space and R^q."""

    __slots__ = ("J", "dense", "q", "G", "factor")

    def __init__(self, J: Jacobian) -> None:
        self.J = J
        self.dense = type(J) is np.ndarray
        self.q = q = J.shape[0]
        self.factor = None
        if q == 0:
            return
        G = np.dot(J, J.T) if self.dense else np.asarray((J @ J.T).toarray(), dtype=float)
        if q == 1:  # scalar: skip LAPACK
            self.G = float(G[0, 0])
            if not (self.G > 0.0 and math.isfinite(self.G)):
                raise _Degenerate
            return
        factor = factorize_spd(G, what="normal matrix Jh Jh^T of the constraints")
        pivots = np.diagonal(factor.L)
        if float(np.min(pivots)) ** 2 <= _DEGENERATE * float(np.max(np.diagonal(G))):
            raise _Degenerate  # rank-deficient Jh: the min-norm steps are unreliable
        self.factor = factor

    def coefficients(self, b: np.ndarray) -> np.ndarray:
        """``G^{-1} b``; b: (q,)."""
        if self.factor is None:
            return b / self.G if self.q else b
        return self.factor.solve(b)

    def lift(self, y: np.ndarray) -> np.ndarray:
        """``Jh^T y`` (n,); y: (q,)."""
        return np.dot(y, self.J) if self.dense else self.J.T @ y

    def apply(self, a: np.ndarray) -> np.ndarray:
        """``Jh a`` (q,); a: (n,)."""
        return np.dot(self.J, a) if self.dense else self.J @ a


class _Degenerate(Exception):
    """Jh has (numerically) dependent rows at the current point."""


class _Budget(Exception):
    """The evaluation budget ran out."""


class _Slider:
    """State of one :func:`project_on_manifold` call."""

    def __init__(self, evaluate: Evaluate, w_star, tol_constraint, tol_step, max_evaluations) -> None:
        self.evaluate_fn = evaluate
        self.w_star = w_star
        self.tol_constraint = tol_constraint
        self.tol_step = tol_step
        self.max_evaluations = max_evaluations
        self.evaluations = 0
        self.history: list[tuple] = []

    def evaluate(self, x: np.ndarray) -> tuple[np.ndarray, Jacobian, float]:
        if self.evaluations >= self.max_evaluations:
            raise _Budget
        self.evaluations += 1
        return self.evaluate_fn(x)

    def cost(self, x: np.ndarray) -> float:
        a = x - self.w_star
        return float(np.dot(a, a))

    def restore(self, x, h, J, err, record: bool):
        """Min-norm Gauss-Newton steps onto ``h = 0`` from an evaluated ``x``.

        Adds each accepted point to the history when ``record`` (restoration of the start).
        Returns ``(x, h, err, normal)`` at a point with ``max|h| <= tol_constraint`` and G
        factorized there, or None when ``||h||`` cannot be reduced.
        """
        target = _RESTORE_RTOL * self.tol_constraint
        hh = float(np.dot(h, h))
        while True:
            normal = _Normal(J)
            if err <= target:
                return x, h, err, normal
            step = normal.lift(normal.coefficients(h))  # x - step solves the linearized h = 0
            scale = 1.0
            for _ in range(_MAX_HALVINGS):
                trial = x - scale * step
                try:
                    h_t, J_t, err_t = self.evaluate(trial)
                except ArithmeticError:  # NaN or inf at the trial point (NumericalError)
                    h_t = None
                if h_t is not None:
                    hh_t = float(np.dot(h_t, h_t))
                    if hh_t <= (1.0 - _ARMIJO * scale) * hh:  # ||h||^2 predicted to drop by 2 scale ||h||^2
                        break
                if err <= self.tol_constraint:  # feasible, and h no longer drops: rounding level
                    return x, h, err, normal
                scale *= 0.5
            else:
                return None
            if record:
                step_norm = scale * math.sqrt(np.dot(step, step))
                self.history.append((self.evaluations, self.cost(trial), err_t, step_norm, trial))
            x, h, J, err, hh = trial, h_t, J_t, err_t, hh_t

    def tangent(self, x: np.ndarray, normal: _Normal) -> tuple[np.ndarray, np.ndarray]:
        """``v = P (w* - x)`` (n,) and ``y = G^{-1} Jh (w* - x)`` (q,)."""
        a = self.w_star - x
        y = normal.coefficients(normal.apply(a))
        return a - normal.lift(y), y

    def run(self, x0: np.ndarray) -> ManifoldProjection | None:
        h, J, err = self.evaluate(x0)
        self.history.append((self.evaluations, self.cost(x0), err, 0.0, x0))
        restored = self.restore(x0, h, J, err, True)
        if restored is None:
            return None
        x, h, err, normal = restored
        f = self.cost(x)
        v, y = self.tangent(x, normal)
        alpha, rejected = 1.0, 0
        while True:
            vv = float(np.dot(v, v))
            xx = float(np.dot(x, x))
            if math.sqrt(vv) <= self.tol_step * (1.0 + math.sqrt(xx)):
                return ManifoldProjection(x, h, err, f, 2.0 * y, self.evaluations, self.history)
            # Tangent step and restoration; f(x + alpha v) ~ f - 2 alpha ||v||^2 to first order.
            predicted = 2.0 * alpha * vv
            noise = _NOISE * (f + xx + float(np.dot(self.w_star, self.w_star)))
            trial = x + alpha * v
            try:
                h_t, J_t, err_t = self.evaluate(trial)
                restored = self.restore(trial, h_t, J_t, err_t, False)
            except (_Degenerate, ArithmeticError):  # singular G or NaN there: a shorter step
                restored = None
            if restored is not None:
                x_t, h_t, err_t, normal_t = restored
                f_t = self.cost(x_t)
                if f - f_t >= _ARMIJO * predicted or (predicted <= noise and f_t <= f + noise):
                    v_t, y_t = self.tangent(x_t, normal_t)
                    # Barzilai-Borwein length: s^T s / s^T (v - v_t), the inverse curvature along s.
                    s, dv = x_t - x, v - v_t
                    ss, sy = float(np.dot(s, s)), float(np.dot(s, dv))
                    alpha = min(max(ss / sy, _ALPHA_MIN), _ALPHA_MAX) if sy > 0.0 else min(2.0 * alpha, _ALPHA_MAX)
                    self.history.append((self.evaluations, f_t, err_t, math.sqrt(ss), x_t))
                    x, h, err, f, v, y, rejected = x_t, h_t, err_t, f_t, v_t, y_t, 0
                    continue
            if predicted <= noise:  # even a step at rounding level fails: nothing left to gain
                return ManifoldProjection(x, h, err, f, 2.0 * y, self.evaluations, self.history)
            rejected += 1
            if rejected > _MAX_HALVINGS:
                return None
            alpha *= 0.5


def project_on_manifold(
    evaluate: Evaluate,
    w_star: np.ndarray,
    w_init: np.ndarray,
    *,
    tol_constraint: float,
    tol_step: float,
    max_evaluations: int,
) -> ManifoldProjection | None:
    """Closest point to ``w_star`` on ``h(w) = 0`` near ``w_init`` (Eq. 18), or None.

    Parameters
    ----------
    evaluate : ``x (n,) -> (h (q,), Jh (q, n), max|h|)``, already validated by the caller; it
        raises ``NumericalError`` (an ``ArithmeticError``) for NaN or inf.
    w_star : (n,) point to project.
    w_init : (n,) start (need not be feasible).
    tol_constraint : required ``max |h|``.
    tol_step : stop when the tangent step ``||v|| <= tol_step (1 + ||x||)``.
    max_evaluations : budget of calls of ``evaluate``.

    Returns
    -------
    ManifoldProjection, or None when the method gave up (degenerate Jacobian, restoration or
    line search failure, budget); the caller should then use a more robust method.
    """
    slider = _Slider(evaluate, w_star, tol_constraint, tol_step, max_evaluations)
    try:
        return slider.run(w_init)
    except (_Degenerate, _Budget, ArithmeticError):  # NaN at the start: the fallback reports it
        return None
