"""Motion optimization of Sec. V-A and VI, in two floors.

The representation (this package's modules): :class:`BSpline` is the reference trajectory
``xi(w, t) = B(t) w`` (time-major ``w.reshape(P, Q)``, :mod:`~corl.trajectory.bspline`);
:mod:`~corl.trajectory.features` and :mod:`~corl.trajectory.taskspace` build squared cost features
(Eq. 7, 9) and equality features (Eq. 6) with sparse Jacobians and stack them into a
:class:`TrajectoryProblem` (a banded affine cost when the features are linear); :mod:`~corl.trajectory.phase`
re-times a trajectory with fixed geometry (Eq. 10).

The solver (:mod:`corl.trajectory.solver`, which knows least-squares problems, not trajectories):
:func:`solve` minimises ``J = r^T r`` under ``h(w) = 0`` and a trust region
``||w - center|| <= radius`` (Eq. 8) by SQP / Newton-KKT steps on a banded Hessian where the
problem has one, else by an augmented Lagrangian around damped Gauss-Newton steps;
:func:`project` is the machinery of Eq. 18 (public as :func:`corl.realise.realise`).

Algorithm 1 schedules the steps (:class:`corl.learner.CORL`). Neither floor knows of tasks.
"""

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
from corl.trajectory.solver.banded import BandedSPD, SupportGram
from corl.trajectory.solver.linalg import factorize_spd, solve_spd, trust_region_step

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
