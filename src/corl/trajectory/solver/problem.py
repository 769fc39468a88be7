"""Problem, configuration and result types of :mod:`corl.trajectory.solver` (Eq. 7-8, Eq. 18).

:class:`LeastSquaresProblem` is what :func:`~corl.trajectory.solver.solve` minimises
(``J = r^T r`` under ``h(w) = 0``); :class:`FunctionProblem` builds one from two callables.
:class:`SolverConfig` holds the tolerances and budgets (``SolverConfig()`` the defaults, and
the named presets ``trajectory`` and ``precise``); :class:`SolveResult` and :class:`IterationRecord` report what
:func:`~corl.trajectory.solver.solve` and :func:`~corl.trajectory.solver.project` did.
This module knows nothing of the algorithm and imports nothing else of the solver package.

Glossary
--------
w          : decision variables (trajectory parameters), (n,)
r, Jr      : cost residuals (p,) and their Jacobian dr/dw (p, n); J = r^T r (Eq. 7)
h, Jh      : equality constraints (q,) and their Jacobian dh/dw (q, n); h(w) stands for h(w, theta)
mu         : penalty weight of the augmented Lagrangian
damping    : Levenberg-Marquardt multiple of the identity added to the Gauss-Newton Hessian
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any, Callable, NamedTuple, Protocol, runtime_checkable

import numpy as np

from corl import checks
from corl.errors import InputError

__all__ = [
    "LeastSquaresProblem",
    "FunctionProblem",
    "SolverConfig",
    "SolverMethod",
    "IterationRecord",
    "SolveResult",
]

Jacobian = Any  # np.ndarray or scipy.sparse matrix, (rows, n)

DAMPING_FLOOR = 1e-15  # smallest damping, relative to the largest diagonal entry of H


# ---------------------------------------------------------------------------------------------
# Problem interface
# ---------------------------------------------------------------------------------------------
@runtime_checkable
class LeastSquaresProblem(Protocol):
    """A sum-of-squares cost with equality constraints (Eq. 7-8)."""

    def residuals(self, w: np.ndarray) -> tuple[np.ndarray, Jacobian]:
        """Residuals ``r`` (p,) and Jacobian ``dr/dw`` (p, n), dense or scipy.sparse; ``J = r @ r``."""

    def equalities(self, w: np.ndarray) -> tuple[np.ndarray, Jacobian]:
        """Constraints ``h`` (q,) and Jacobian ``dh/dw`` (q, n), dense or scipy.sparse; q may be 0."""


class FunctionProblem:
    """A :class:`LeastSquaresProblem` made of two callables.

    Parameters
    ----------
    residuals_fn : ``w (n,) -> (r (p,), dr/dw (p, n))``.
    equalities_fn : ``w (n,) -> (h (q,), dh/dw (q, n))``, or None for an unconstrained problem.
    """

    def __init__(
        self,
        residuals_fn: Callable[[np.ndarray], tuple[np.ndarray, Jacobian]],
        equalities_fn: Callable[[np.ndarray], tuple[np.ndarray, Jacobian]] | None = None,
    ) -> None:
        if not callable(residuals_fn):
            raise InputError(f"residuals_fn must be callable w -> (r, dr/dw), got {residuals_fn!r}")
        if equalities_fn is not None and not callable(equalities_fn):
            raise InputError(f"equalities_fn must be callable w -> (h, dh/dw) or None, got {equalities_fn!r}")
        self._residuals_fn = residuals_fn
        self._equalities_fn = equalities_fn

    def residuals(self, w: np.ndarray) -> tuple[np.ndarray, Jacobian]:
        return self._residuals_fn(w)

    def equalities(self, w: np.ndarray) -> tuple[np.ndarray, Jacobian]:
        if self._equalities_fn is None:
            return np.zeros(0), np.zeros((0, w.shape[0]))
        return self._equalities_fn(w)




# ---------------------------------------------------------------------------------------------
# Configuration and result
# ---------------------------------------------------------------------------------------------
class SolverMethod(str, Enum):
    """How :func:`~corl.trajectory.solver.solve` treats the equality constraints of Eq. 8.

    AUGMENTED_LAGRANGIAN ("al") : multiplier updates around damped Gauss-Newton steps on L_A; any problem.
    SQP ("sqp") : Newton-KKT steps on ``h = 0`` with the Schur complement of a banded Hessian and a
        merit line search (:mod:`corl.trajectory.solver.sqp`), for problems with a banded affine cost
        (``affine_cost``) and equalities; other problems, and the few states where an SQP step is
        not available (rank-deficient ``dh/dw``, constraints out of reach of the ball), use the
        augmented Lagrangian.
    """

    AUGMENTED_LAGRANGIAN = "al"
    SQP = "sqp"


@checks.keywords()
@dataclass(frozen=True)
class SolverConfig:
    """Settings of :func:`~corl.trajectory.solver.solve`.

    Attributes
    ----------
    tol_constraint : feasibility tolerance on ``max |h|``.
    tol_step : an inner solve has converged when the Gauss-Newton step satisfies
        ``||dw|| <= tol_step * (1 + ||w||)``.
    max_iterations : budget of Gauss-Newton iterations over all outer iterations (each one
        evaluates the problem once, rejected steps included).
    max_outer_iterations : budget of augmented-Lagrangian multiplier updates.
    mu_init : first penalty, relative: ``mu = mu_init * maxdiag(Jr^T Jr) / maxdiag(Jh^T Jh)`` at
        the start (ratio 1 when either is zero), so the penalty starts on the scale of the cost.
    mu_growth : factor by which mu grows when ``||h||`` did not shrink by ``violation_decrease``.
    mu_max : largest penalty, as a multiple of the first one; beyond it the constraints are
        declared unsatisfiable.
    violation_decrease : required factor of decrease of ``||h||`` per outer iteration.
    inner_rtol : inexact inner solves before a multiplier update stop once the step is below
        ``inner_rtol`` times their first accepted step (0 for exact solves); the final solve is always tight.
    damping_init : first Levenberg-Marquardt damping, relative to the largest diagonal entry of H.
    damping_max : relative damping at which no decrease of L_A is possible any more (stall).
    method : :class:`SolverMethod` (or its value ``"al"`` / ``"sqp"``); SQP by default, which
        runs only on problems with a banded affine cost and equalities (a
        :class:`~corl.trajectory.features.TrajectoryProblem` of linear cost features, e.g. a
        task's ``trajectory_problem``) and leaves every other problem to the augmented Lagrangian;
        ``"al"`` forces the augmented Lagrangian everywhere. The penalty settings (``mu_*``,
        ``violation_decrease``, ``inner_rtol``, ``max_outer_iterations``) and the damping apply
        to the augmented Lagrangian only (and to it when SQP hands over).
    """

    tol_constraint: float = 1e-6
    tol_step: float = 1e-10
    max_iterations: int = 200
    max_outer_iterations: int = 50
    mu_init: float = 1.0
    mu_growth: float = 10.0
    mu_max: float = 1e10
    violation_decrease: float = 0.25
    inner_rtol: float = 1e-2
    damping_init: float = 1e-12
    damping_max: float = 1e12
    method: SolverMethod = SolverMethod.SQP

    def __post_init__(self) -> None:
        if type(self.method) is not SolverMethod:
            try:
                object.__setattr__(self, "method", SolverMethod(self.method))
            except (ValueError, TypeError):
                choices = ", ".join(repr(m.value) for m in SolverMethod)
                raise InputError(
                    f"SolverConfig.method must be a SolverMethod or one of {choices}, got {self.method!r}"
                ) from None
        for name in ("tol_constraint", "tol_step", "mu_init", "mu_max", "damping_init", "damping_max"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise InputError(f"SolverConfig.{name} must be a positive finite number, got {value!r}")
        for name in ("max_iterations", "max_outer_iterations"):
            value = getattr(self, name)
            if not (isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 1):
                raise InputError(f"SolverConfig.{name} must be an integer >= 1, got {value!r}")
        if not (math.isfinite(self.mu_growth) and self.mu_growth > 1):
            raise InputError(f"SolverConfig.mu_growth must be > 1, got {self.mu_growth!r}")
        if not (0 <= self.inner_rtol < 1):
            raise InputError(f"SolverConfig.inner_rtol must be in [0, 1), got {self.inner_rtol!r}")
        if not (0 < self.violation_decrease < 1):
            raise InputError(f"SolverConfig.violation_decrease must be in (0, 1), got {self.violation_decrease!r}")
        if self.mu_max < 1:
            raise InputError(
                f"SolverConfig.mu_max is relative to the first penalty and must be >= 1, got {self.mu_max!r}"
            )
        if not (DAMPING_FLOOR <= self.damping_init < self.damping_max):
            raise InputError(
                f"SolverConfig needs {DAMPING_FLOOR:g} <= damping_init < damping_max, "
                f"got damping_init={self.damping_init!r}, damping_max={self.damping_max!r}"
            )

    @classmethod
    def trajectory(cls) -> SolverConfig:
        """B-spline trajectories with acceleration costs (Eq. 9) and contact constraints (Eq. 6):
        SQP steps on the banded Hessian (iterations independent of the number of knots),
        max|h| <= 1e-8, a penalty 1e-4 x the relative default (the cost's Hessian scales with
        1/dt^4, so the default penalty would dwarf it) and loose inner solves for the augmented
        Lagrangian fallback (tuned on ``benchmarks/motion_opt.py``)."""
        return cls(
            tol_constraint=1e-8,
            tol_step=1e-9,
            max_iterations=500,
            mu_init=1e-4,
            inner_rtol=0.3,
            method=SolverMethod.SQP,
        )

    @classmethod
    def precise(cls) -> SolverConfig:
        """Tight tolerances (max|h| <= 1e-10) for reference solutions and tests."""
        return cls(tol_constraint=1e-10, tol_step=1e-13, max_iterations=1000, max_outer_iterations=100)


class IterationRecord(NamedTuple):
    """State after one accepted Gauss-Newton step (record 0 is the start).

    Attributes
    ----------
    iteration : Gauss-Newton iterations done so far (rejected steps included).
    outer : augmented-Lagrangian iteration the step belongs to.
    cost : ``J(w) = r^T r``.
    constraint_error : ``max |h(w)|`` (0 without constraints).
    step_norm : ``||w - w_previous||``.
    damping : Levenberg-Marquardt damping used for the step (absolute); for an SQP step the
        multiplier of the trust-region ball (0 when the ball is not active).
    mu : penalty weight at the time of the step; for an SQP step that of its merit function.
    w : (n,) the iterate.
    """

    iteration: int
    outer: int
    cost: float
    constraint_error: float
    step_norm: float
    damping: float
    mu: float
    w: np.ndarray


@dataclass(frozen=True)
class SolveResult:
    """Outcome of :func:`~corl.trajectory.solver.solve` or :func:`~corl.trajectory.solver.project`.

    Attributes
    ----------
    w : (n,) the solution (always inside the trust region).
    cost : ``J(w) = r^T r`` at the solution.
    constraint_error : ``max |h(w)|``.
    multipliers : (q,) Lagrange multipliers ``nu`` of h with ``grad J + Jh^T nu ~ 0`` (plus the
        ball's normal when the trust region is active).
    converged : True when the inner problem converged and ``constraint_error <= tol_constraint``.
    status : what happened, in words (why it stopped and what to change if it failed).
    iterations : Gauss-Newton or SQP iterations (rejected steps and backtracks included: one per
        evaluation after the start).
    outer_iterations : augmented-Lagrangian iterations (1 when SQP converged on its own).
    evaluations : calls of ``residuals`` (each paired with one call of ``equalities``).
    trust_region_active : True when ``||w - center||`` is at the radius.
    history : one :class:`IterationRecord` per accepted step, the start first.
    """

    w: np.ndarray
    cost: float
    constraint_error: float
    multipliers: np.ndarray
    converged: bool
    status: str
    iterations: int
    outer_iterations: int
    evaluations: int
    trust_region_active: bool
    history: tuple[IterationRecord, ...]
