"""Motion optimization of Sec. V-A and VI: B-spline trajectories, k-order Markov features, the
trust-region step of Eq. 8, phase optimization (Eq. 10) and the projection of Eq. 18.

:class:`BSpline` is the reference trajectory ``xi(w, t) = B(t) w`` (time-major ``w.reshape(P, Q)``);
:mod:`corl.trajectory.features` builds squared features (Eq. 7, 9) and equality features (Eq. 6)
with sparse Jacobians and stacks them into a :class:`TrajectoryProblem`. :func:`solve` minimises
``J = r^T r`` under ``h(w) = 0`` and a trust region ``||w - center|| <= radius``, by one of two
methods (``SolverConfig.method``): an augmented Lagrangian around damped Gauss-Newton steps, or an
SQP / Newton-KKT step (:mod:`corl.trajectory.sqp`, :mod:`corl.trajectory.kkt`: the Schur
complement on the constraint rows, the ball handled exactly, the augmented Lagrangian as merit
and fallback), which ``SolverConfig.trajectory()`` picks for long trajectories. Both factorize
banded Cholesky systems (:mod:`corl.trajectory.banded`). :func:`project` is Eq. 18. :mod:`corl.trajectory.phase`
re-times a trajectory with fixed geometry (Alg. 1 schedules the steps:
:class:`corl.learner.CORL`). Solvers know nothing of tasks.
"""

from corl.trajectory.banded import BandedSPD, SupportGram
from corl.trajectory.bspline import BSpline
from corl.trajectory.features import (
    JointLimitFeature,
    LinearFeature,
    TaskSpaceFeature,
    TrajectoryProblem,
    acceleration_feature,
    configuration_feature,
    velocity_feature,
)
from corl.trajectory.linalg import factorize_spd, solve_spd, trust_region_step
from corl.trajectory.phase import (
    PhaseConfig,
    PhaseResult,
    RetimeResult,
    optimize_phase,
    phase_cost,
    retime,
)
from corl.trajectory.solver import (
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
    "IterationRecord",
    "SolveResult",
    "solve",
    "project",
    "factorize_spd",
    "solve_spd",
    "trust_region_step",
    "BandedSPD",
    "SupportGram",
    "BSpline",
    "LinearFeature",
    "JointLimitFeature",
    "TaskSpaceFeature",
    "TrajectoryProblem",
    "acceleration_feature",
    "velocity_feature",
    "configuration_feature",
    "PhaseConfig",
    "PhaseResult",
    "RetimeResult",
    "optimize_phase",
    "phase_cost",
    "retime",
]
