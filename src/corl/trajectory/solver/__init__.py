"""The motion optimizer: Eq. 8 (:func:`solve`) and the machinery of Eq. 18 (:func:`project`).

It knows least-squares problems, not trajectories or tasks: a problem gives residuals ``r`` (J =
r^T r, Eq. 7) and equalities ``h`` (Eq. 6) with their Jacobians, and optionally the structure that
the fast path uses (``affine_cost``, ``affine_transpose``, ``equalities_on_support``,
``equality_curvature``, ``gauss_newton_band``, ``distance_problem``: see
:mod:`corl.trajectory.solver.model`); the trajectory representation
(:mod:`corl.trajectory.features`) builds such problems.

Layout, from the entry points down:

* :mod:`~corl.trajectory.solver.driver` : :func:`solve` and :func:`project`; picks the strategy.
* :mod:`~corl.trajectory.solver.sqp` : SQP / Newton-KKT steps on a banded Hessian (the default
  for banded problems) with a merit line search.
* :mod:`~corl.trajectory.solver.al` : the augmented Lagrangian around damped Gauss-Newton steps
  (any problem; SQP's fallback).
* :mod:`~corl.trajectory.solver.manifold` : Eq. 18 by restoration and tangent steps along h = 0.
* :mod:`~corl.trajectory.solver.state` : :class:`SolveState`, what the strategies share (ball,
  damping, counters, history); :mod:`~corl.trajectory.solver.model` : :class:`Iterate`, one
  evaluation of the problem, and the Gauss-Newton model built from it.
* :mod:`~corl.trajectory.solver.kkt`, :mod:`~corl.trajectory.solver.factor`,
  :mod:`~corl.trajectory.solver.condense`, :mod:`~corl.trajectory.solver.linalg`,
  :mod:`~corl.trajectory.solver.banded` : the linear algebra (Schur complement on banded
  Cholesky factors, Dirichlet rows and condensation on the constraint window, trust-region
  steps, LAPACK band storage).
* :mod:`~corl.trajectory.solver.problem` : the problem protocol, :class:`SolverConfig`,
  :class:`SolveResult`.
"""

from corl.trajectory.solver.driver import project, solve
from corl.trajectory.solver.problem import (
    FunctionProblem,
    IterationRecord,
    LeastSquaresProblem,
    SolveResult,
    SolverConfig,
    SolverMethod,
)

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
