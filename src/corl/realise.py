"""Eq. 18 in public: the trajectory that realises a theta, closest to a given ``w*``.

Alg. 1, step 2 turns every theta the black-box method asks for into a trajectory::

    w = argmin_w ||L (w - w*)||^2   s.t.  h(w, theta) = 0                        (Eq. 18)

with ``L`` the identity (the paper) or the task's ``projection_metric``. :func:`realise` is the one
implementation: the learner (:class:`corl.learner.CORL`), the door benchmark's safe region and
``corl sweep`` all call it, so a theta is realised the same way wherever it is measured.

Glossary
--------
w*, theta*   : the anchor trajectory (n,) and the theta it realises (m,); usually the learner's best
theta        : (m,) the interaction parameters to realise
L            : the task's projection metric, a sparse (rows, n) matrix, or None for the identity
feasible     : ``max |h(w, theta)| <= FEASIBILITY_FACTOR * solver.tol_constraint``
continuation : theta* -> theta in equal pieces, each projection anchored at the previous result

Eq. 18 may have no minimiser (its infimum can sit where ``dh/dw`` is singular); any feasible point
realises theta and is accepted. When the direct projection stays infeasible, theta is reached by
continuation (8 pieces, then 64), which follows the constraint manifold instead of cutting across it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl.errors import InputError
from corl.numerics import as_vector
from corl.problem import Demonstration, Task, check_theta, constraint_of
from corl.trajectory.solver import FunctionProblem, LeastSquaresProblem, SolveResult, SolverConfig, project

__all__ = ["FEASIBILITY_FACTOR", "DEMONSTRATION_TOLERANCE", "Realisation", "realise", "motion_problem", "feasible",
           "constraint_violation", "check_demonstration", "project_demonstration"]

FEASIBILITY_FACTOR = 10.0  # a realisation is feasible when max|h| <= this x SolverConfig.tol_constraint
DEMONSTRATION_TOLERANCE = 1e-3  # default of CORLConfig.demo_tolerance: max|h(w0, theta0)| in h's units
_CONTINUATION = (8, 64)  # pieces of the continuation from theta* to theta, tried in turn


@dataclass(frozen=True)
class Realisation:
    """The result of :func:`realise`.

    Attributes
    ----------
    w : (n,) the trajectory; realises ``theta`` when ``feasible``.
    theta : (m,) the theta asked for.
    feasible : ``max |h(w, theta)|`` is within the feasibility tolerance.
    constraint_error : ``max |h(w, theta)|`` of ``w``.
    pieces : 0 for the direct projection, else the number of continuation pieces used.
    status : the solver's status of the last projection.
    result : the last projection's :class:`corl.trajectory.solver.SolveResult`.
    """

    w: np.ndarray
    theta: np.ndarray
    feasible: bool
    constraint_error: float
    pieces: int
    status: str
    result: SolveResult


def feasible(result: SolveResult, solver: SolverConfig = SolverConfig()) -> bool:
    """True when a projection's ``max |h|`` is within ``FEASIBILITY_FACTOR * solver.tol_constraint``."""
    return bool(result.constraint_error <= FEASIBILITY_FACTOR * solver.tol_constraint)


def motion_problem(task: Task, theta) -> LeastSquaresProblem:
    """The task's motion problem at ``theta`` (m,): ``J`` (Eq. 7) under ``h(., theta) = 0`` (Eq. 6).

    The task's own structured problem when it gives one (``trajectory_problem``,
    :class:`corl.problem.HasTrajectoryProblem`: the banded SQP path of the solver), else the two
    callables ``cost_residuals`` and ``constraint`` (the augmented Lagrangian).
    """
    theta = np.asarray(theta, dtype=float)
    structured = getattr(task, "trajectory_problem", None)  # corl.problem.HasTrajectoryProblem
    if structured is None:
        h = constraint_of(task)
        return FunctionProblem(task.cost_residuals, lambda w: h(w, theta))
    problem = structured(theta)
    if not isinstance(problem, LeastSquaresProblem):
        raise InputError(f"task '{task.name}': trajectory_problem(theta) returned {type(problem).__name__}; it must "
                         "return a corl.trajectory.TrajectoryProblem (residuals J, equalities h(., theta))")
    return problem


def _project_once(task: Task, theta, anchor, solver: SolverConfig = SolverConfig()) -> SolveResult:
    """One projection (Eq. 18) of ``anchor`` (n,) onto ``h(., theta) = 0``, in the task's metric.

    The paper's Euclidean distance ``||w - w*||`` moves only the few B-spline control points around
    each constrained time, so the motion bends there and returns to its old path in between. A task
    with a ``projection_metric`` (sparse ``L``, (rows, n)) gets the closest trajectory in
    ``||L (w - w*)||`` instead (e.g. accelerations: a smooth deformation). The solve itself is
    :func:`corl.trajectory.solver.project` on :func:`motion_problem` (SQP for a structured task).
    """
    anchor = as_vector(anchor, name="anchor w")
    metric = getattr(task, "projection_metric", None)  # corl.problem.HasProjectionMetric
    return project(motion_problem(task, theta), anchor, metric=metric, config=solver)


def realise(task: Task, w_star, theta_star, theta, solver: SolverConfig = SolverConfig()) -> Realisation:
    """Eq. 18: the trajectory closest to ``w_star`` (n,) that realises ``theta`` (m,).

    Parameters
    ----------
    task : the task (its ``constraint`` gives h; its ``projection_metric``, if any, the metric of Eq. 18).
    w_star : (n,) the anchor, e.g. the learner's best trajectory or the demonstration's ``w0``.
    theta_star : (m,) the theta ``w_star`` realises: the start of the continuation.
    theta : (m,) the theta to realise; must lie in ``task.theta_bounds``.
    solver : tolerances of the projections (the learner passes ``CORLConfig.solver``).

    Returns
    -------
    Realisation
        ``feasible`` False when neither the direct projection nor the continuation satisfied h:
        the theta cannot be realised from this anchor (the learner tells it as a failure without a
        rollout).
    """
    w_star = as_vector(w_star, name="w_star")
    theta_star = check_theta(theta_star, task.theta_bounds, task=task.name)
    theta = check_theta(theta, task.theta_bounds, task=task.name)
    result = _project_once(task, theta, w_star, solver)
    if feasible(result, solver):
        return _realisation(result, theta, 0, solver)
    for pieces in _CONTINUATION:
        w = w_star
        for k in range(1, pieces + 1):
            step_theta = theta_star + (theta - theta_star) * (k / pieces)
            result = _project_once(task, step_theta, w, solver)
            if not feasible(result, solver):
                break
            w = result.w
        else:
            return _realisation(result, theta, pieces, solver)
    return _realisation(result, theta, _CONTINUATION[-1], solver)


def _realisation(result: SolveResult, theta: np.ndarray, pieces: int, solver: SolverConfig) -> Realisation:
    return Realisation(w=result.w, theta=theta, feasible=feasible(result, solver),
                       constraint_error=float(result.constraint_error), pieces=pieces, status=result.status,
                       result=result)


def constraint_violation(task: Task, w, theta) -> float:
    """``max |h(w, theta)|``: how far ``w`` (n,) is from realising ``theta`` (m,)."""
    h, _ = constraint_of(task)(as_vector(w, name="w"), np.asarray(theta, dtype=float))
    h = np.asarray(h, dtype=float)
    return float(np.max(np.abs(h))) if h.size else 0.0


def check_demonstration(task: Task, demonstration: Demonstration | None = None,
                        tolerance: float = DEMONSTRATION_TOLERANCE) -> Demonstration:
    """Check that the demonstration satisfies ``h(w0, theta0) = 0`` before anything is rolled out.

    ``tolerance`` bounds ``max |h(w0, theta0)|`` in h's units (the learner passes
    ``CORLConfig.demo_tolerance``, 1e-3 by default: a millimetre where h is a contact position).
    It is looser than the feasibility of a projection, since a recorded demonstration is fitted,
    but tight enough that a fit which misses its waypoints by millimetres is caught instead of being
    silently moved by the first optimization step.

    Returns the demonstration as vectors; raises :class:`corl.errors.InputError` naming how far it
    is and how to fix it (:func:`project_demonstration`).
    """
    demo = task.demonstration() if demonstration is None else demonstration
    if not isinstance(demo, Demonstration):
        raise InputError(f"task '{task.name}': demonstration() returned {type(demo).__name__}; it must return "
                         "corl.problem.Demonstration(w, theta)")
    w0 = as_vector(demo.w, name=f"demonstration().w of task '{task.name}'")
    theta0 = check_theta(demo.theta, task.theta_bounds, task=task.name)
    violation = constraint_violation(task, w0, theta0)
    if not violation <= tolerance:
        raise InputError(
            f"the demonstration of task '{task.name}' does not satisfy h: max|h(w0, theta0)| = {violation:.3g} > "
            f"tolerance {tolerance:.3g} (CORLConfig.demo_tolerance); project it onto h = 0 with "
            "corl.realise.project_demonstration(task, demo) and return that from task.demonstration() "
            "(or give the theta0 that w0 realises, task.theta_of(w0))")
    return Demonstration(w0, theta0)


def project_demonstration(task: Task, demonstration: Demonstration | None = None,
                          solver: SolverConfig = SolverConfig()) -> tuple[Demonstration, float, float]:
    """The demonstration moved onto ``h(w, theta0) = 0`` (Eq. 18 from ``w0``, in the task's metric).

    Returns
    -------
    (Demonstration, before, moved)
        the projected demonstration, ``max |h(w0, theta0)|`` before, and ``||w - w0||``: how far the
        trajectory had to move (report it: a large move means the demonstration was poorly fitted).

    Raises
    ------
    InputError
        When the projection does not become feasible (theta0 is out of reach of w0).
    """
    demo = task.demonstration() if demonstration is None else demonstration
    w0 = as_vector(demo.w, name="demonstration w")
    theta0 = check_theta(demo.theta, task.theta_bounds, task=task.name)
    before = constraint_violation(task, w0, theta0)
    result = _project_once(task, theta0, w0, solver)
    if not feasible(result, solver):
        raise InputError(f"the demonstration of task '{task.name}' cannot be projected onto h = 0 "
                         f"(max|h| {result.constraint_error:.3g} after projection, {result.status}); "
                         "check theta0 and the waypoints the demonstration was fitted to")
    return Demonstration(result.w, theta0), before, float(np.linalg.norm(result.w - w0))
