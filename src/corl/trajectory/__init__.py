"""Motion optimization of Sec. VI: the trust-region step of Eq. 8 and the projection of Eq. 18.

:func:`solve` minimises a sum of squares ``J = r^T r`` (Eq. 7) under equality constraints
``h(w) = 0`` and a trust region ``||w - center|| <= radius`` with an augmented Lagrangian around
damped Gauss-Newton steps; :func:`project` is Eq. 18 (restoration and tangent steps along
``h = 0``, with :func:`solve` as fallback). Solvers know nothing of tasks.
"""

from corl.trajectory.linalg import factorize_spd, solve_spd, trust_region_step
from corl.trajectory.solver import (
    DEFAULT_CONFIG,
    FunctionProblem,
    IterationRecord,
    LeastSquaresProblem,
    SolveResult,
    SolverConfig,
    project,
    solve,
)

__all__ = [
    "LeastSquaresProblem",
    "FunctionProblem",
    "SolverConfig",
    "DEFAULT_CONFIG",
    "IterationRecord",
    "SolveResult",
    "solve",
    "project",
    "factorize_spd",
    "solve_spd",
    "trust_region_step",
]
