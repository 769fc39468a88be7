"""The synthetic benchmark of Sec. VIII-A (Fig. 1).

    J(w)        = (w1^2 + w2^2 - 1)^2            analytic cost, residual r(w) = w1^2 + w2^2 - 1
    R(theta)    = -0.5 theta^2 + cos(3 theta)    black-box return
    S(theta)    = [-1.5 < theta < 2.5]           black-box success
    h(w, theta) = atan2(w2, w1) - theta          the constraint, theta in (-pi, pi]

The paper writes ``h = theta - atan(w1 / w2)`` but also states the optimum ``w* = (1, 0)`` with value
-1. Both hold only for ``theta = atan2(w2, w1)``: then ``theta* = 0``, ``R(0) = 1`` and ``J(w*) = 0``.
We use that reading (DESIGN.md). ``w`` is searched in ``[-1.5, 1.5]^2`` by the methods over ``w``.

Near the boundary (within ``critical_distance`` of it, on the feasible side) a rollout also
reports ``info["boundary_distance"]``, the safety measure only SAL uses.
"""

from __future__ import annotations

import math

import numpy as np

from corl.errors import InputError
from corl.problem import Bounds, Demonstration, Outcome

__all__ = ["SyntheticTask", "ContextualSyntheticTask", "optimum_of", "CONTEXT_BOUNDS", "SAFE_LOW", "SAFE_HIGH", "W_OPT",
           "distance_to_safe"]

SAFE_LOW, SAFE_HIGH = -1.5, 2.5
W_OPT = np.array([1.0, 0.0])


def distance_to_safe(theta: float) -> float:
    """Distance in theta from ``theta`` to the safe interval (-1.5, 2.5) (0 inside)."""
    return float(max(SAFE_LOW - theta, theta - SAFE_HIGH, 0.0))


def return_of(theta: float) -> float:
    return -0.5 * theta**2 + math.cos(3.0 * theta)


class SyntheticTask:
    """The 2-D benchmark problem; ``w0`` is a feasible start (use :meth:`random_start`)."""

    name = "synthetic"
    theta_bounds = Bounds(np.array([-math.pi]), np.array([math.pi]))
    w_bounds = Bounds(np.array([-1.5, -1.5]), np.array([1.5, 1.5]))

    def __init__(self, w0=(0.5, 0.5), *, critical_distance: float = 0.5) -> None:
        w0 = np.asarray(w0, dtype=float)
        if w0.shape != (2,) or not np.all(np.isfinite(w0)) or np.hypot(*w0) == 0:
            raise InputError(f"w0 must be a non-zero finite 2-vector, got {w0}")
        self.w0 = w0
        self.critical_distance = float(critical_distance)

    @staticmethod
    def random_start(rng: np.random.Generator) -> np.ndarray:
        """A start uniform in ``[-1.5, 1.5]^2`` with ``S(theta(w)) = 1`` (rejection sampling)."""
        while True:
            w = rng.uniform(-1.5, 1.5, size=2)
            theta = math.atan2(w[1], w[0])
            if SAFE_LOW < theta < SAFE_HIGH and np.hypot(*w) > 1e-3:
                return w

    def demonstration(self) -> Demonstration:
        return Demonstration(self.w0.copy(), self.theta_of(self.w0))

    def method_settings(self):
        """The paper's fixed GP values and budgets for this benchmark (Sec. VIII-A, Fig. 1)."""
        from corl.settings import PAPER_SYNTHETIC

        return PAPER_SYNTHETIC

    def cost_residuals(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = w[0] * w[0] + w[1] * w[1] - 1.0
        return np.array([r]), np.array([[2.0 * w[0], 2.0 * w[1]]])

    def constraint(self, w: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rho2 = max(w[0] * w[0] + w[1] * w[1], 1e-300)
        diff = math.atan2(w[1], w[0]) - float(theta[0])
        diff = (diff + math.pi) % (2.0 * math.pi) - math.pi  # the angle difference on the circle
        return np.array([diff]), np.array([[-w[1] / rho2, w[0] / rho2]])

    def theta_of(self, w: np.ndarray) -> np.ndarray:
        return np.array([math.atan2(w[1], w[0])])

    def rollout(self, w: np.ndarray) -> Outcome:
        theta = math.atan2(w[1], w[0])
        if not SAFE_LOW < theta < SAFE_HIGH:
            return Outcome(False, None, {"theta": theta})
        info = {"theta": theta}
        margin = min(theta - SAFE_LOW, SAFE_HIGH - theta)
        if margin < self.critical_distance:
            info["boundary_distance"] = margin
        return Outcome(True, return_of(theta), info)


#: The synthetic family's context box: one coordinate ``c`` in [-1, 1].
CONTEXT_BOUNDS = Bounds(np.array([-1.0]), np.array([1.0]))
SHIFT, STRETCH = 0.5, 0.2  # theta*(c) = SHIFT c; the circle of J has radius 1 + STRETCH c


def optimum_of(c: float) -> tuple[float, np.ndarray]:
    """The closed-form optimum of :class:`ContextualSyntheticTask` in context ``c``: ``(theta*, w*)``."""
    theta = SHIFT * float(c)
    rho = 1.0 + STRETCH * float(c)
    return theta, rho * np.array([math.cos(theta), math.sin(theta)])


class ContextualSyntheticTask(SyntheticTask):
    """The synthetic benchmark with one context ``c`` in [-1, 1] (a scene that moves):

        J(w; c)        = (w1^2 + w2^2 - rho(c)^2)^2,    rho(c) = 1 + 0.2 c
        R(theta; c)    = -0.5 (theta - 0.5 c)^2 + cos(3 (theta - 0.5 c))
        S(theta; c)    = [-1.5 < theta - 0.5 c < 2.5]
        h(w, theta)    = atan2(w2, w1) - theta            (theta keeps its meaning: an angle)

    so ``theta*(c) = 0.5 c``, ``R = 1`` there and ``w*(c) = rho(c) (cos theta*, sin theta*)``
    (:func:`optimum_of`). ``c = 0`` is the paper's problem. The demonstration is recorded in the
    task's own context; it succeeds in every context of the box (its theta is inside every S).
    """

    name = "synthetic-context"
    context_bounds = CONTEXT_BOUNDS
    context_labels = ("scene shift c",)

    def __init__(self, w0=(0.5, 0.5), *, critical_distance: float = 0.5, context=0.0) -> None:
        from corl.problem import check_theta

        super().__init__(w0, critical_distance=critical_distance)
        self.context = check_theta(context, CONTEXT_BOUNDS, task=self.name, what="context")

    def with_context(self, c) -> "ContextualSyntheticTask":
        return ContextualSyntheticTask(self.w0, critical_distance=self.critical_distance, context=c)

    def best_return(self) -> float:
        """The best return in this scene, in closed form: R = 1 at theta*(c) = 0.5 c (:func:`optimum_of`)."""
        return 1.0

    @property
    def _shift(self) -> float:
        return SHIFT * float(self.context[0])

    def cost_residuals(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        rho = 1.0 + STRETCH * float(self.context[0])
        r = w[0] * w[0] + w[1] * w[1] - rho * rho
        return np.array([r]), np.array([[2.0 * w[0], 2.0 * w[1]]])

    def rollout(self, w: np.ndarray) -> Outcome:
        theta = math.atan2(w[1], w[0])
        u = theta - self._shift
        info = {"theta": theta}
        if not SAFE_LOW < u < SAFE_HIGH:
            return Outcome(False, None, info)
        margin = min(u - SAFE_LOW, SAFE_HIGH - u)
        if margin < self.critical_distance:
            info["boundary_distance"] = margin
        return Outcome(True, return_of(u), info)
