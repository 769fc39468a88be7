"""The state of one :func:`~corl.trajectory.solver.solve` call, shared by its step strategies.

:func:`~corl.trajectory.solver.solve` builds one :class:`SolveState` and hands it, with the current
:class:`~corl.trajectory.solver.model.Iterate`, to the strategy that takes the steps: SQP
(:func:`corl.trajectory.solver.sqp.sqp`) and, where SQP has no step or does not apply, the
augmented Lagrangian (:func:`corl.trajectory.solver.al.augmented_lagrangian`). Both count their
evaluations and iterations here, record their accepted points here, and keep their trial points
inside the same trust-region ball; the augmented Lagrangian also keeps its Levenberg-Marquardt
damping here.

Glossary
--------
w                : decision variables, (n,)
center, radius   : the trust-region ball ``||w - center|| <= radius`` (eps_max of Eq. 8); center None without one
damping          : Levenberg-Marquardt multiple of the identity added to the Gauss-Newton Hessian
scale            : largest diagonal entry of the first Hessian (damping is relative to it)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from corl.trajectory.solver.model import Iterate, evaluate_problem, max_diagonal, sumsq
from corl.trajectory.solver.problem import DAMPING_FLOOR, IterationRecord, Jacobian, LeastSquaresProblem, SolverConfig

__all__ = ["SolveState"]


@dataclass(eq=False)
class SolveState:
    """Mutable state of one solve: the problem, the ball, the damping, counters and history.

    Attributes
    ----------
    problem : the :class:`~corl.trajectory.solver.problem.LeastSquaresProblem`.
    config : its :class:`~corl.trajectory.solver.problem.SolverConfig`.
    center : (n,) center of the trust region, or None without one.
    radius : its radius (``inf`` without one).
    damping : current Levenberg-Marquardt damping (absolute; 0 until the first Hessian sets the scale).
    damping_start, damping_floor, damping_ceiling : its first, smallest and largest values.
    scale : largest diagonal entry of the first Hessian.
    growth : Nielsen's factor by which the damping grows on consecutive rejections.
    iterations : steps tried so far (each evaluates the problem once; rejected steps included).
    evaluations : calls of the problem (the start included).
    outer : current augmented-Lagrangian outer iteration (0 for SQP).
    history : one :class:`~corl.trajectory.solver.problem.IterationRecord` per accepted point, the start first.
    recheck : whether ``center + z`` can round outside the ball, so new points need their distance checked.
    """

    problem: LeastSquaresProblem
    config: SolverConfig
    center: np.ndarray | None
    radius: float
    damping: float = 0.0
    damping_start: float = 0.0
    damping_floor: float = 0.0
    damping_ceiling: float = 0.0
    scale: float = 1.0
    growth: float = 2.0
    iterations: int = 0
    evaluations: int = 0
    outer: int = 0
    history: list[IterationRecord] = field(default_factory=list)
    recheck: bool = field(init=False)

    def __post_init__(self) -> None:
        # center + z rounds by at most 1.12e-16 (||center|| + radius) in norm; recheck the distance
        # of new points only when that could exceed 1e-12 radius.
        center, radius = self.center, self.radius
        self.recheck = center is not None and 2.3e-16 * (math.sqrt(sumsq(center)) + radius) > 1e-12 * radius

    def evaluate(self, w: np.ndarray) -> Iterate:
        """The problem at ``w`` (n,), counted."""
        self.evaluations += 1
        return evaluate_problem(self.problem, w)

    def record(self, pt: Iterate, step_norm: float, damping: float, mu: float) -> None:
        """Append an accepted point to the history (``damping``/``mu`` as :class:`IterationRecord` describes)."""
        self.history.append(IterationRecord(self.iterations, self.outer, pt.rr, pt.err, step_norm, damping, mu, pt.w))

    def set_damping_scale(self, H: Jacobian) -> None:
        """Scale the damping to the first Hessian ``H`` (n, n): start, floor and ceiling relative to maxdiag(H)."""
        scale = max_diagonal(H)
        scale = scale if scale > 0 and math.isfinite(scale) else 1.0
        self.scale = scale
        self.damping = self.damping_start = self.config.damping_init * scale
        self.damping_floor = DAMPING_FLOOR * scale
        self.damping_ceiling = self.config.damping_max * scale

    def new_point(self, w: np.ndarray, d: np.ndarray, z: np.ndarray | None) -> np.ndarray:
        """``w + d`` (n,), placed exactly on the ball when the step ended on its boundary (``z``: its
        offset from the center, or None when the ball is not active)."""
        if z is None:
            return w + d
        w_new = self.center + z
        if not self.recheck:
            return w_new
        offset = w_new - self.center
        dist = math.sqrt(sumsq(offset))
        if dist > self.radius:  # rounding in center + z
            w_new = self.center + offset * (self.radius / dist)
        return w_new

    def on_boundary(self, w: np.ndarray) -> bool:
        """True when ``w`` (n,) is on the ball's boundary (up to 1e-9 relative); False without a ball."""
        if self.center is None:
            return False
        return math.sqrt(sumsq(w - self.center)) >= self.radius * (1.0 - 1e-9)
