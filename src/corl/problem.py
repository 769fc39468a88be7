"""The structured problem of Eq. 2-5 and the records a learning loop exchanges.

Glossary
--------
w       : trajectory (policy) parameters, shape (n,); n >= 1000 on a robot
theta   : interaction parameters, shape (m,), m = 1..4 (e.g. where the fingers touch a handle)
J(w)    : analytic cost, known in closed form; here always a sum of squares ``J = r(w) @ r(w)`` (Eq. 7)
h(w, theta) : projection constraint (Eq. 2, Eq. 6), shape (q,); ``h = 0`` ties w to theta
R(theta): black-box return (Eq. 3), higher is better
S(theta): black-box success (Eq. 4), True or False

A task is anything that has the attributes and methods of :class:`Task`. The synthetic benchmark
and the door are two implementations; a user's own robot task plugs in the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Protocol, runtime_checkable

import numpy as np

from corl.errors import InputError
from corl.numerics import as_vector

__all__ = ["Bounds", "Outcome", "Proposal", "Demonstration", "Task", "check_theta"]


@dataclass(frozen=True)
class Bounds:
    """A box ``lower <= x <= upper``; ``lower``, ``upper``: (m,)."""

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self) -> None:
        lower = as_vector(self.lower, name="lower bound")
        upper = as_vector(self.upper, len(lower), name="upper bound")
        if np.any(lower >= upper):
            raise InputError(f"bounds need lower < upper in every coordinate, got {lower} and {upper}")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)

    @property
    def dim(self) -> int:
        return int(self.lower.shape[0])

    @property
    def width(self) -> np.ndarray:
        return self.upper - self.lower

    def contains(self, x: np.ndarray, tol: float = 1e-12) -> bool:
        x = np.asarray(x, dtype=float)
        return bool(np.all(x >= self.lower - tol) and np.all(x <= self.upper + tol))

    def clip(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.asarray(x, dtype=float), self.lower, self.upper)

    def to_unit(self, x: np.ndarray) -> np.ndarray:
        """Map points in the box to ``[0, 1]^m``; ``x``: (..., m)."""
        return (np.asarray(x, dtype=float) - self.lower) / self.width

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        """Map points of ``[0, 1]^m`` into the box; ``u``: (..., m)."""
        return self.lower + np.asarray(u, dtype=float) * self.width


def check_theta(theta, bounds: Bounds, *, task: str = "task") -> np.ndarray:
    """Validate a theta against a task's bounds and return it as a float vector (m,)."""
    arr = np.asarray(theta, dtype=float)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.shape != (bounds.dim,):
        raise InputError(f"theta has shape {arr.shape}, expected ({bounds.dim},) for task '{task}'")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"theta contains NaN or infinite values: {arr}")
    if not bounds.contains(arr):
        raise InputError(
            f"theta {np.array2string(arr, precision=4)} is outside the bounds of task '{task}': "
            f"lower {np.array2string(bounds.lower, precision=4)}, upper {np.array2string(bounds.upper, precision=4)}"
        )
    return arr


@dataclass(frozen=True)
class Outcome:
    """What one rollout reports: success ``S`` and return ``R`` (Eq. 3-4).

    ``return_`` must be a finite number when ``success`` is True. After a failure it may be None
    (the usual case on a robot: no return is observed) or a finite number, which safe methods
    ignore. ``info`` carries anything else the task measured (door angle, forces, ...); it must be
    JSON-serializable to be stored.
    """

    success: bool
    return_: float | None = None
    info: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.success, (bool, np.bool_)):
            raise InputError(f"success must be True or False, got {self.success!r}")
        object.__setattr__(self, "success", bool(self.success))
        if self.return_ is not None:
            try:
                value = float(self.return_)
            except (TypeError, ValueError):
                raise InputError(f"return must be a number, got {self.return_!r}") from None
            if not math.isfinite(value):
                raise InputError(
                    f"return is {value}; a rollout must report a finite return "
                    "(report the trial as a failure without a return if nothing was measured)"
                )
            object.__setattr__(self, "return_", value)
        elif self.success:
            raise InputError("a successful outcome needs a finite return (R is observed on success)")


@dataclass(frozen=True)
class Demonstration:
    """The initial policy ``(w0, theta0)`` of Alg. 1, assumed successful: ``S(theta0) = 1``."""

    w: np.ndarray
    theta: np.ndarray


@dataclass(frozen=True)
class Proposal:
    """One trial a learner asks to execute.

    Attributes
    ----------
    index : position of this trial in the run, 0-based.
    w : (n,) trajectory parameters to execute.
    theta : (m,) interaction parameters ``w`` realises (``h(w, theta) = 0``).
    step : which part of Alg. 1 proposed it: "demonstration", "optimization", "phase",
        "reinforcement" (CORL); "search" for a black-box method over ``w``.
    round : outer iteration of Alg. 1 (0-based).
    """

    index: int
    w: np.ndarray
    theta: np.ndarray
    step: str
    round: int = 0


@runtime_checkable
class Task(Protocol):
    """What CORL needs from a manipulation task (Eq. 2-5, Sec. IV).

    Attributes
    ----------
    name : short name used in messages and files.
    theta_bounds : the box ``theta`` is searched in, (m,) each.
    w_bounds : a box for methods that search ``w`` directly, or None.

    Optional members the learner uses when present: ``method_settings()`` (hyperparameters in the
    task's units), ``projection_metric`` (sparse ``L``: Eq. 18 in ``||L (w - w*)||``), ``spline``
    (enables phase steps, Eq. 10), ``retimed(time_map)`` (a copy whose time-indexed constraints
    hold at ``time_map(times)``: phase steps then move the contact instants) or ``pinned_times``
    (times whose phase stays fixed), ``reference(w, rate)`` (the joint trajectory ``corl ask`` writes).
    """

    name: str
    theta_bounds: Bounds
    w_bounds: Bounds | None

    def demonstration(self) -> Demonstration:
        """The initial successful policy ``(w0, theta0)``; ``h(w0, theta0)`` should be ~0."""

    def cost_residuals(self, w: np.ndarray) -> tuple[np.ndarray, Any]:
        """Residuals ``r (p,)`` and Jacobian ``dr/dw (p, n)`` (ndarray or scipy.sparse): ``J(w) = r @ r``."""

    def projection(self, w: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, Any]:
        """``h(w, theta)`` (q,) and its Jacobian ``dh/dw`` (q, n) (Eq. 2, Eq. 6)."""

    def theta_of(self, w: np.ndarray) -> np.ndarray:
        """The unique ``theta`` with ``h(w, theta) = 0`` (the projection Theta(w)), (m,)."""

    def rollout(self, w: np.ndarray) -> Outcome:
        """Execute the policy with parameters ``w`` (n,) and report the black-box ``R`` and ``S``."""
