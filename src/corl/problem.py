"""The structured problem of Eq. 2-5 and the records a learning loop exchanges.

Glossary
--------
w       : trajectory (policy) parameters, shape (n,); n >= 1000 on a robot
theta   : interaction parameters, shape (m,), m = 1..4 (e.g. where the fingers touch a handle)
J(w)    : analytic cost, known in closed form; here always a sum of squares ``J = r(w) @ r(w)`` (Eq. 7)
h(w, theta) : the constraint (the paper's "projection", Eq. 2, Eq. 6), shape (q,); ``h = 0`` ties w
          to theta; a task gives it as ``constraint(w, theta)``. "Projection" in corl names only Eq. 18,
          the closest trajectory on ``h = 0`` (:func:`corl.realise.realise`)
R(theta): black-box return (Eq. 3), higher is better
S(theta): black-box success (Eq. 4), True or False

A task is anything that has the attributes and methods of :class:`Task`. The synthetic benchmark
and the door are two implementations; a user's own robot task plugs in the same way. Everything
else corl reads from a task is an optional member declared below as a small protocol
(:data:`OPTIONAL_MEMBERS`); corl picks up no other name. :func:`check_task` checks a task before
any rollout.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np

from corl.errors import InputError, TaskError
from corl.numerics import as_vector

__all__ = ["Bounds", "Outcome", "Proposal", "Demonstration", "Task", "check_theta", "HasMethodSettings",
           "HasTrajectoryProblem", "HasProjectionMetric", "HasSpline", "Retimable", "HasPinnedTimes", "HasReference",
           "HasJointNames", "HasThetaLabels", "RendersComparison", "RollsOutInWorker", "HasContexts", "context_of", "REQUIRED_MEMBERS", "OPTIONAL_MEMBERS",
           "DEPRECATED_MEMBERS", "constraint_of", "check_task", "check_reference", "task_error"]


@dataclass(frozen=True)
class Bounds:
    """A box ``lower <= x <= upper``; ``lower``, ``upper``: (m,)."""

    lower: np.ndarray
    upper: np.ndarray

    def __post_init__(self) -> None:
        lower = as_vector(self.lower, name="lower bound")
        upper = as_vector(self.upper, len(lower), name="upper bound")
        if lower.shape[0] == 0:
            raise InputError("bounds are empty: give lower and upper with one entry per dimension of theta (m >= 1)")
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


def check_theta(theta, bounds: Bounds, *, task: str = "task", what: str = "theta") -> np.ndarray:
    """Validate a theta (or another point, named ``what``: "context") against a task's bounds and
    return it as a float vector (m,)."""
    arr = np.asarray(theta, dtype=float)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.shape != (bounds.dim,):
        raise InputError(f"{what} has shape {arr.shape}, expected ({bounds.dim},) for task '{task}'")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what} contains NaN or infinite values: {arr}")
    if not bounds.contains(arr):
        below, above = bounds.lower - arr, arr - bounds.upper  # > 0 where outside (printed to 4 digits, it may not show)
        j = int(np.argmax(np.maximum(below, above)))
        side, gap, edge = ("below", below[j], bounds.lower[j]) if below[j] > 0 else ("above", above[j], bounds.upper[j])
        raise InputError(
            f"{what} {np.array2string(arr, precision=4)} is outside the bounds of task '{task}': "
            f"lower {np.array2string(bounds.lower, precision=4)}, upper {np.array2string(bounds.upper, precision=4)} "
            f"(coordinate {j}, {float(arr[j])!r}, is {float(gap):.3g} {side} {float(edge)!r})"
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
            except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond a float (10**400)
                raise InputError(f"return must be a finite number, got {str(self.return_)[:40]}") from None
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
    """The initial policy ``(w0, theta0)`` of Alg. 1, assumed successful: ``S(theta0) = 1``.

    Attributes
    ----------
    w : (n,) the demonstration's trajectory parameters ``w0``.
    theta : (m,) the interaction parameters it realises, ``h(w0, theta0) ~ 0`` (checked at the start
        of a run: :func:`corl.realise.check_demonstration`; fix with :func:`corl.realise.project_demonstration`).
    """

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
        "reinforcement" (CORL); "skill" for the start of a run in a new context that a skill
        proposed (:mod:`corl.contexts`); "search" for a black-box method over ``w``.
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

    Notes
    -----
    The optional members corl uses when present are the protocols below (:data:`OPTIONAL_MEMBERS`):
    ``method_settings()``, ``trajectory_problem(theta)``, ``projection_metric``, ``spline``, ``retimed(time_map)``,
    ``pinned_times``, ``reference(w, rate)``, ``joint_names``, ``theta_labels``,
    ``render_comparison(w_demo, w_learned, path)``.
    """

    name: str
    theta_bounds: Bounds
    w_bounds: Bounds | None

    def demonstration(self) -> Demonstration:
        """The initial successful policy ``(w0, theta0)``; ``h(w0, theta0)`` must be ~0 (checked)."""

    def cost_residuals(self, w: np.ndarray) -> tuple[np.ndarray, Any]:
        """Residuals ``r (p,)`` and Jacobian ``dr/dw (p, n)`` (ndarray or scipy.sparse): ``J(w) = r @ r``."""

    def constraint(self, w: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, Any]:
        """The constraint ``h(w, theta)`` (q,) and its Jacobian ``dh/dw`` (q, n) (Eq. 2, Eq. 6).

        Formerly named ``projection``; a task that still has ``projection`` and no
        ``constraint`` works, with a FutureWarning (:func:`constraint_of`)."""

    def theta_of(self, w: np.ndarray) -> np.ndarray:
        """The unique ``theta`` with ``h(w, theta) = 0`` (the projection Theta(w)), (m,)."""

    def rollout(self, w: np.ndarray) -> Outcome:
        """Execute the policy with parameters ``w`` (n,) and report the black-box ``R`` and ``S``."""


# -- optional members: each a small protocol, each read by one part of corl -----------------------
@runtime_checkable
class HasMethodSettings(Protocol):
    """``method_settings()`` returns a :class:`corl.settings.MethodSettings`: GP hyperparameters in the
    task's units, Algorithm 1's trust region, budgets (read by ``make_method``; default: the synthetic
    benchmark's, which suit theta of size ~1)."""

    def method_settings(self) -> Any: ...


@runtime_checkable
class HasProjectionMetric(Protocol):
    """``projection_metric``: a sparse ``L`` (rows, n); Eq. 18 then minimises ``||L (w - w*)||`` instead
    of ``||w - w*||`` (:func:`corl.realise.realise`), e.g. accelerations for a smooth deformation."""

    projection_metric: Any


@runtime_checkable
class HasTrajectoryProblem(Protocol):
    """``trajectory_problem(theta)``: the motion problem of Eq. 8 at ``theta`` (m,) as a
    :class:`corl.trajectory.TrajectoryProblem` built from features: its residuals are the task's
    ``cost_residuals`` (J, Eq. 7) and its equalities the task's h (``constraint(w, theta)``, Eq. 6).

    A task that gives it opts in to the banded SQP solver (:mod:`corl.trajectory.solver.sqp`):
    Alg. 1's step 1 (Eq. 8), the phase steps and Eq. 18 (:func:`corl.realise.realise`, with the
    cost swapped for the distance to ``w*`` by :meth:`~corl.trajectory.TrajectoryProblem.with_costs`)
    then run Newton-KKT steps on the banded Hessian of a linear cost (acceleration features). Without
    it, or when the cost is not linear, the augmented Lagrangian solves the same problems from
    ``cost_residuals`` and ``constraint``. Cache the problem per theta: the learner asks once per
    optimization round and once per Eq. 18."""

    def trajectory_problem(self, theta: np.ndarray) -> Any: ...


@runtime_checkable
class HasSpline(Protocol):
    """``spline``: the :class:`corl.trajectory.BSpline` behind ``w``; enables phase steps (Eq. 10) when
    ``CORLConfig.max_phase_steps > 0``."""

    spline: Any


@runtime_checkable
class Retimable(Protocol):
    """``retimed(time_map)``: a copy of the task whose time-indexed constraints hold at
    ``time_map(times)``; phase steps then move the contact instants with the phase."""

    def retimed(self, time_map) -> "Task": ...


@runtime_checkable
class HasPinnedTimes(Protocol):
    """``pinned_times``: times (s) whose phase a phase step keeps (for a task without ``retimed``)."""

    pinned_times: Sequence[float]


@runtime_checkable
class HasReference(Protocol):
    """``reference(w, rate)``: the joint trajectory a robot follows for ``w`` (``corl ask`` writes it).

    Contract: returns ``(t, q)``, times ``t`` (K,) in seconds from 0, increasing, sampled at ``rate``
    Hz (``t[1] - t[0] == 1 / rate``), and joint positions ``q`` (K, Q), one column per joint
    (``joint_names`` names them). :func:`check_reference` enforces it.
    """

    def reference(self, w: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]: ...


@runtime_checkable
class HasJointNames(Protocol):
    """``joint_names``: Q names, the columns of ``reference``'s ``q`` (the CSV header of ``corl ask``)."""

    joint_names: Sequence[str]


@runtime_checkable
class HasThetaLabels(Protocol):
    """``theta_labels``: m axis labels of theta for the return map and the report."""

    theta_labels: Sequence[str]


@runtime_checkable
class RendersComparison(Protocol):
    """``render_comparison(w_demo, w_learned, path)``: a video of both motions side by side, written to
    ``path`` (a ``.mp4``); returns the path written (``corl run`` and ``corl report``)."""

    def render_comparison(self, w_demo: np.ndarray, w_learned: np.ndarray, path) -> Any: ...


@runtime_checkable
class RollsOutInWorker(Protocol):
    """``rollout_in_worker = True``: a simulator whose ``rollout(w)`` is a pure function of ``w`` that
    changes nothing the learner reads. ``corl run`` then rolls it out in a forked process while CORL
    computes its next motion step (:mod:`corl.tasks.worker`, Linux only): the same trials on two
    cores. Never for a real robot's task (it would be forked): a robot task that subclasses a
    simulated one (e.g. to reuse the door's constraints) sets ``rollout_in_worker = False``."""

    rollout_in_worker: bool


@runtime_checkable
class HasContexts(Protocol):
    """Contexts (one skill, many scenes): what the robot measures before a trial and cannot choose.

    ``context_bounds``: the :class:`Bounds` of the context ``c`` (k,), e.g. a door's pose and
    handle height; ``context``: this task's own context (k,), inside the box; ``with_context(c)``:
    the same task in context ``c``, a task whose ``context`` is ``c``. ``theta`` keeps its meaning
    and ``w`` its layout (n,) across contexts; ``h``, ``J`` and the rollout are those of scene ``c``.
    The demonstration is recorded once, in one context; ``with_context(c).demonstration()`` may be
    a demonstration in ``c`` (what learning from scratch there starts from). Optional:
    ``context_labels``, k axis labels; ``best_return()``, the best return reachable in this
    task's own scene (a closed form, or a dense search its author ran: ``corl bench contexts``
    scores every method against it, :func:`corl.experiments.contexts.parse_truth`).
    :mod:`corl.contexts` learns across contexts.
    """

    context_bounds: Bounds
    context: Any

    def with_context(self, c) -> "Task": ...


REQUIRED_MEMBERS = {"name": False, "theta_bounds": False, "w_bounds": False, "demonstration": True,
                    "cost_residuals": True, "constraint": True, "theta_of": True, "rollout": True}  # name: callable?
OPTIONAL_MEMBERS = {"method_settings": (HasMethodSettings, True),
                    "trajectory_problem": (HasTrajectoryProblem, True),
                    "projection_metric": (HasProjectionMetric, False),
                    "spline": (HasSpline, False), "retimed": (Retimable, True),
                    "pinned_times": (HasPinnedTimes, False), "reference": (HasReference, True),
                    "joint_names": (HasJointNames, False), "theta_labels": (HasThetaLabels, False),
                    "render_comparison": (RendersComparison, True),
                    "rollout_in_worker": (RollsOutInWorker, False),
                    "with_context": (HasContexts, True), "context_bounds": (HasContexts, False),
                    "context": (HasContexts, False), "context_labels": (HasContexts, False),
                    "best_return": (HasContexts, True)}


DEPRECATED_MEMBERS = {"projection": "constraint"}  # old name -> new name; read only when the new one is absent


def constraint_of(task) -> Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, Any]]:
    """The task's constraint ``(w, theta) -> (h (q,), dh/dw (q, n))``: ``task.constraint``, or the old
    name ``task.projection`` with a FutureWarning (renamed: "projection" now names only Eq. 18)."""
    fn = getattr(task, "constraint", None)
    if fn is not None:
        return fn
    old = getattr(task, "projection", None)
    if old is None:
        raise InputError(f"task '{getattr(task, 'name', '?')}' has no constraint(w, theta) (see corl.problem.Task)")
    warnings.warn(f"task '{getattr(task, 'name', '?')}' ({type(task).__name__}) gives h as projection(w, theta); "
                  "rename it to constraint(w, theta) (the old name will be removed)", FutureWarning, stacklevel=2)
    return old


def task_error(exc: BaseException, trial: int, doing: str = "as the learner took in") -> TaskError | None:
    """``exc`` as a :class:`TaskError` naming the task's member that raised it (the outermost frame of its
    traceback named like a member of :class:`Task` or :data:`OPTIONAL_MEMBERS`) and ``trial``; None when no
    such frame is in it (then it is no error of the task's code)."""
    names = {m for m, method in REQUIRED_MEMBERS.items() if method} | set(DEPRECATED_MEMBERS) \
        | {m for m, (_, method) in OPTIONAL_MEMBERS.items() if method}
    tb = exc.__traceback__
    while tb is not None and tb.tb_frame.f_code.co_name not in names:
        tb = tb.tb_next
    if tb is None:
        return None
    member, detail = tb.tb_frame.f_code.co_name, " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
    return TaskError(f"the task's {member} raised {detail}, {doing} trial {trial}", member=member, trial=trial,
                     detail=detail)


def check_task(task, source: str = "the task") -> Task:
    """Check the members of a task before any rollout; one :class:`InputError` naming what is wrong.

    Required members must exist (methods callable, ``theta_bounds`` a :class:`Bounds`); optional
    members, where present, must have the right kind (a method callable, ``joint_names`` and
    ``theta_labels`` sequences of strings of the right length).
    """
    where = f"{source} ({type(task).__name__})"
    missing = [a for a in REQUIRED_MEMBERS if not hasattr(task, a)
               and not any(new == a and hasattr(task, old) for old, new in DEPRECATED_MEMBERS.items())]
    if missing:
        raise InputError(f"{where} is not a task: it lacks {', '.join(missing)}; "
                         "add them (see corl.problem.Task and the README's task protocol)")
    for member, is_method in REQUIRED_MEMBERS.items():
        if not hasattr(task, member):  # present under its deprecated name (checked above)
            member = next(old for old, new in DEPRECATED_MEMBERS.items() if new == member)
        if is_method and not callable(getattr(task, member)):
            raise InputError(f"{where}: '{member}' must be a method (see corl.problem.Task)")
    constraint_of(task)  # warns here, before any rollout, when the task still calls h projection
    if not isinstance(task.theta_bounds, Bounds):
        raise InputError(f"{where}: theta_bounds must be a corl.problem.Bounds, got {type(task.theta_bounds).__name__}")
    if task.w_bounds is not None and not isinstance(task.w_bounds, Bounds):
        raise InputError(f"{where}: w_bounds must be a corl.problem.Bounds or None, got {type(task.w_bounds).__name__}")
    for member, (_, is_method) in OPTIONAL_MEMBERS.items():
        value = getattr(task, member, None)
        if value is not None and is_method and not callable(value):
            raise InputError(f"{where}: the optional member '{member}' must be a method or absent "
                             f"(see corl.problem.{OPTIONAL_MEMBERS[member][0].__name__})")
    _check_contexts(task, where)
    if getattr(task, "rollout_in_worker", None) not in (None, True, False):
        raise InputError(f"{where}: 'rollout_in_worker' must be True or False, got "
                         f"{getattr(task, 'rollout_in_worker')!r:.40} (see corl.problem.RollsOutInWorker)")
    for member, size in (("theta_labels", task.theta_bounds.dim), ("joint_names", None)):
        value = getattr(task, member, None)
        if value is None:
            continue
        if isinstance(value, str) or not all(isinstance(v, str) for v in value):
            raise InputError(f"{where}: '{member}' must be a sequence of strings, got {value!r}")
        if size is not None and len(value) != size:
            raise InputError(f"{where}: '{member}' has {len(value)} entries, theta has {size}; give one per coordinate")
    return task


def _check_contexts(task, where: str) -> None:
    """The context members come together: ``context_bounds`` a Bounds, ``context`` inside it,
    ``with_context`` a method, ``context_labels`` one string per context coordinate."""
    present = [m for m in ("with_context", "context_bounds", "context") if getattr(task, m, None) is not None]
    if not present:
        return
    if len(present) < 3:
        missing = sorted({"with_context", "context_bounds", "context"} - set(present))
        raise InputError(f"{where} has {', '.join(present)} but lacks {', '.join(missing)}; a task with contexts "
                         "gives all three (see corl.problem.HasContexts)")
    if not isinstance(task.context_bounds, Bounds):
        raise InputError(f"{where}: context_bounds must be a corl.problem.Bounds, got {type(task.context_bounds).__name__}")
    context_of(task)
    labels = getattr(task, "context_labels", None)
    if labels is not None and (isinstance(labels, str) or len(labels) != task.context_bounds.dim
                               or not all(isinstance(v, str) for v in labels)):
        raise InputError(f"{where}: 'context_labels' must be {task.context_bounds.dim} strings, got {labels!r}")


def context_of(task) -> np.ndarray | None:
    """The task's own context (k,) checked against its ``context_bounds``, or None for a task without
    contexts (:class:`HasContexts`)."""
    bounds = getattr(task, "context_bounds", None)
    if bounds is None or getattr(task, "with_context", None) is None:
        return None
    try:
        return check_theta(getattr(task, "context", None), bounds, task=getattr(task, "name", "task"), what="context")
    except (TypeError, ValueError):
        raise InputError(f"task '{getattr(task, 'name', '?')}': context must be {bounds.dim} numbers inside "
                         f"context_bounds, got {getattr(task, 'context', None)!r:.60}") from None


def check_reference(task, t, q, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Check what ``task.reference(w, rate)`` returned against its contract (:class:`HasReference`).

    Returns ``t`` (K,) and ``q`` (K, Q) as float arrays; raises :class:`InputError` naming the member.
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    what = f"task '{getattr(task, 'name', '?')}': reference(w, rate)"
    if t.ndim != 1 or q.ndim != 2 or q.shape[0] != t.shape[0] or t.shape[0] < 1:
        raise InputError(f"{what} returned t {t.shape} and q {q.shape}; it must return times (K,) and joint "
                         "positions (K, Q), one row per time (see corl.problem.HasReference)")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise InputError(f"{what} returned NaN or infinite values")
    if t.shape[0] > 1:
        dt = np.diff(t)
        if not np.allclose(dt, 1.0 / rate, rtol=1e-6, atol=1e-9):
            raise InputError(f"{what} ignored the rate: time steps {dt.min():.6g}..{dt.max():.6g} s, expected "
                             f"1/{rate:g} Hz = {1.0 / rate:.6g} s (see corl.problem.HasReference)")
    names = getattr(task, "joint_names", None)
    if names is not None and len(names) != q.shape[1]:
        raise InputError(f"{what} returned {q.shape[1]} joints but joint_names has {len(names)}; "
                         "give one name per column of q")
    return t, q
