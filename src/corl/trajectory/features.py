"""k-order Markov squared features on B-spline trajectories (Eq. 7, Eq. 9) and equality features (Eq. 6).

The analytic cost of Eq. 7 is ``J(w) = sum_t v_t phi_t(x_t)^2`` over the discretized trajectory
``x_t = xi(w, t dt)``, ``t = 0..K``, ``dt = T / K``. A feature maps w to a vector ``phi`` and its
SPARSE Jacobian ``dphi/dw``; the solver's residuals are the weighted features ``sqrt(v_t) phi_t``
so that ``r^T r = J`` (Eq. 7).

* Velocity (k = 1) and acceleration (k = 2, Eq. 9) features are linear in w: ``phi = A w`` with a
  constant sparse A, built once.
* Joint limits: squared hinge ``max(0, x - upper) + min(0, x - lower)``, piecewise linear in w.
* Equalities: a fixed configuration ``h = xi(w, t0) - q0`` (linear) and a task-space point
  ``h = fk(xi(w, t_c)) - target`` (Eq. 6, the contact-point projection), possibly at several times
  of a contact interval with one target each.

:class:`TrajectoryProblem` stacks cost features into one residual vector and equality features into
one constraint vector, a :class:`~corl.trajectory.solver.LeastSquaresProblem` for
:func:`~corl.trajectory.solver.solve`. When every cost feature is linear it also offers the constant
``2 A^T A`` in band storage (``affine_cost``), so the solver never forms ``Jr^T Jr`` again.

Glossary
--------
w, n      : trajectory parameters (n,), time-major (``w.reshape(P, Q)``), n = P Q
K, dt     : number of time steps of the discretization and its step ``T / K``
x_t       : configuration at time ``t dt``, (Q,)
phi, A    : feature values (m,) and, for linear features, their constant Jacobian (m, n): phi = A w - b
v_t       : per-time weights of Eq. 7; the residual is ``sqrt(v_t) phi_t``
fk        : forward kinematics callback ``q (Q,) -> (y (d,), dy/dq (d, Q))``
t_c       : contact time(s) of Eq. 6; ``target`` the task-space point(s) there, (c, d)
h, Jh     : stacked equalities (q,) and their sparse Jacobian (q, n)
"""

from __future__ import annotations

import copy
import math
from typing import Protocol, Sequence, runtime_checkable

import numpy as np
import scipy.sparse as sp

from corl.errors import InputError, NumericalError
from corl.trajectory.solver.banded import BandedSPD, SupportGram, SupportPattern
from corl.trajectory.bspline import BSpline
from corl.trajectory.taskspace import ForwardKinematics, TaskSpaceFeature  # noqa: F401  (re-exported)

__all__ = [
    "Feature",
    "LinearFeature",
    "acceleration_feature",
    "velocity_feature",
    "configuration_feature",
    "JointLimitFeature",
    "TaskSpaceFeature",
    "TrajectoryProblem",
    "stack_csr",
]




@runtime_checkable
class Feature(Protocol):
    """A vector feature of w with a sparse Jacobian."""

    dim: int  # number of rows m

    def __call__(self, w: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """``(phi (m,), dphi/dw (m, n) CSR)``."""


# ---------------------------------------------------------------------------------------------
# Linear features
# ---------------------------------------------------------------------------------------------
class LinearFeature:
    """``phi(w) = A w - b`` with a constant sparse A (m, n) and b (m,)."""

    linear = True

    def __init__(self, A, b=None, *, name: str = "linear feature") -> None:
        self.A = sp.csr_matrix(A, dtype=float)
        self.b = np.zeros(self.A.shape[0]) if b is None else np.asarray(b, dtype=float).ravel()
        if self.b.shape != (self.A.shape[0],):
            raise InputError(f"{name}: b has shape {self.b.shape}, expected ({self.A.shape[0]},)")
        self.name = name
        self._gram: BandedSPD | None = None
        self._transpose: sp.csr_matrix | None = None

    @property
    def dim(self) -> int:
        return self.A.shape[0]

    def transpose(self) -> sp.csr_matrix:
        """``A^T`` (n, m) in CSR, computed once per feature (``A^T r`` by one CSR product)."""
        if self._transpose is None:
            self._transpose = self.A.T.tocsr()
        return self._transpose

    def gram(self) -> BandedSPD:
        """``2 A^T A`` (n, n) in band storage, computed once per feature (the Hessian of ``||A w - b||^2``)."""
        if self._gram is None:
            self._gram = BandedSPD.from_sparse(2.0 * (self.A.T @ self.A).tocsr())
        return self._gram

    def __call__(self, w: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        return self.A @ w - self.b, self.A

    def with_b(self, b: np.ndarray) -> LinearFeature:
        """``A w - b`` for another b (m,): A, its gram and transpose shared (computed at most once)."""
        other = copy.copy(self)
        other.b = np.asarray(b, dtype=float).ravel()
        if other.b.shape != (self.A.shape[0],):
            raise InputError(f"{self.name}: b has shape {other.b.shape}, expected ({self.A.shape[0]},)")
        self.gram()
        self.transpose()
        other._gram, other._transpose = self._gram, self._transpose
        return other


def _weights(weights, count: int, what: str) -> np.ndarray:
    """Per-time weights v_t (count,), from None (all 1), a scalar or a vector; checked >= 0."""
    v = np.ones(count) if weights is None else np.broadcast_to(np.asarray(weights, dtype=float), (count,)).copy()
    if not np.all(np.isfinite(v)) or np.any(v < 0):
        raise InputError(f"{what}: weights v_t must be finite and >= 0 (Eq. 7), got min {v.min():g}")
    return v


def _difference(K: int, order: int) -> sp.csr_matrix:
    """Finite differences of ``order`` on K + 1 samples, ((K + 1 - order), K + 1).

    order 1: ``x_t - x_{t-1}``; order 2: ``x_t - 2 x_{t-1} + x_{t-2}`` (Eq. 9 without 1/dt^2).
    """
    stencil = {1: (-1.0, 1.0), 2: (1.0, -2.0, 1.0)}[order]
    m = K + 1 - order
    return sp.diags(stencil, list(range(order + 1)), shape=(m, K + 1), format="csr")


def _markov_feature(spline: BSpline, num_steps: int, weights, order: int, name: str) -> LinearFeature:
    if not isinstance(num_steps, (int, np.integer)) or num_steps < order:
        raise InputError(f"{name}: num_steps must be an integer >= {order}, got {num_steps!r}")
    dt = float(spline.duration) / num_steps
    v = _weights(weights, num_steps + 1 - order, name)
    # sqrt(v_t) (finite difference of order k of x_t) / dt^k, with x = kron(B, I_Q) w  (Eq. 7, Eq. 9)
    S = sp.diags(np.sqrt(v) / dt**order) @ _difference(num_steps, order) @ spline.basis(spline.grid(num_steps))
    A = sp.kron(S, sp.identity(spline.num_joints, format="csr"), format="csr")
    A.eliminate_zeros()
    return LinearFeature(A, name=name)


def acceleration_feature(spline: BSpline, num_steps: int, weights=None) -> LinearFeature:
    """Squared accelerations of Eq. 9: ``sqrt(v_t) (x_t - 2 x_{t-1} + x_{t-2}) / dt^2``, t = 2..K.

    Parameters
    ----------
    spline : the trajectory basis.
    num_steps : K, the time steps of the discretization ``x_t = xi(w, t dt)``, ``dt = T / K``.
    weights : v_t, scalar or (K - 1,) for t = 2..K; default 1.

    Returns
    -------
    LinearFeature with ``A``: ((K - 1) Q, n); rows time-major.
    """
    return _markov_feature(spline, num_steps, weights, 2, "acceleration feature")


def velocity_feature(spline: BSpline, num_steps: int, weights=None) -> LinearFeature:
    """Squared velocities ``sqrt(v_t) (x_t - x_{t-1}) / dt``, t = 1..K; weights: scalar or (K,).

    Returns a LinearFeature with ``A``: (K Q, n).
    """
    return _markov_feature(spline, num_steps, weights, 1, "velocity feature")


def configuration_feature(spline: BSpline, time: float, q) -> LinearFeature:
    """Equality ``h = xi(w, time) - q`` (Q,), e.g. a fixed start configuration ``xi(w, 0) = q0``."""
    q = np.asarray(q, dtype=float).ravel()
    if q.shape != (spline.num_joints,):
        raise InputError(f"configuration has shape {q.shape}, expected ({spline.num_joints},)")
    A = spline.operator([time])
    A.eliminate_zeros()
    return LinearFeature(A, q, name=f"configuration at t = {time:g}")


# ---------------------------------------------------------------------------------------------
# Nonlinear features
# ---------------------------------------------------------------------------------------------
class JointLimitFeature:
    """Squared hinge joint limits ``sqrt(v) (max(0, x - upper) + min(0, x - lower))`` at given times.

    Parameters
    ----------
    spline : the trajectory basis.
    times : (c,) times in [0, T] where the limits are checked (e.g. ``spline.grid(K)``).
    lower, upper : (Q,) joint limits (``-inf``/``inf`` for none), ``lower <= upper``.
    weight : v > 0.

    Notes
    -----
    The value is (c Q,) time-major; its Jacobian keeps only the rows of violated limits (the
    hinge's derivative is taken as 0 exactly on a limit).
    """

    linear = False

    def __init__(self, spline: BSpline, times, lower, upper, weight: float = 1.0) -> None:
        Q = spline.num_joints
        self.lower = np.broadcast_to(np.asarray(lower, dtype=float), (Q,)).copy()
        self.upper = np.broadcast_to(np.asarray(upper, dtype=float), (Q,)).copy()
        if np.any(self.lower > self.upper) or np.any(np.isnan(self.lower)) or np.any(np.isnan(self.upper)):
            raise InputError("joint limits need lower <= upper for every joint (use -inf/inf for none)")
        if not (math.isfinite(weight) and weight > 0):
            raise InputError(f"joint-limit weight must be positive and finite, got {weight!r}")
        self.operator = spline.operator(times)
        self.scale = math.sqrt(weight)
        count = self.operator.shape[0] // Q
        self.lo, self.hi = np.tile(self.lower, count), np.tile(self.upper, count)

    @property
    def dim(self) -> int:
        return self.operator.shape[0]

    def __call__(self, w: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        x = self.operator @ w
        above, below = x > self.hi, x < self.lo
        value = self.scale * (np.where(above, x - self.hi, 0.0) + np.where(below, x - self.lo, 0.0))
        active = (above | below).astype(float) * self.scale
        op = self.operator
        scaled = op.data * np.repeat(active, np.diff(op.indptr))
        J = sp.csr_matrix((scaled, op.indices.copy(), op.indptr.copy()), shape=op.shape)
        J.eliminate_zeros()  # rows of limits that hold
        return value, J


# ---------------------------------------------------------------------------------------------
# Stacking
# ---------------------------------------------------------------------------------------------
def stack_csr(blocks: Sequence[sp.csr_matrix], n: int) -> sp.csr_matrix:
    """Vertical stack of CSR matrices (m_i, n) by concatenating their arrays (cheaper than sp.vstack)."""
    if len(blocks) == 1:
        return blocks[0]
    if not blocks:
        return sp.csr_matrix((0, n))
    offsets = np.cumsum([0] + [b.nnz for b in blocks[:-1]])
    indptr = np.concatenate([blocks[0].indptr[:1]] + [b.indptr[1:] + o for b, o in zip(blocks, offsets)])
    data = np.concatenate([b.data for b in blocks])
    indices = np.concatenate([b.indices for b in blocks])
    rows = sum(b.shape[0] for b in blocks)
    return sp.csr_matrix((data, indices, indptr), shape=(rows, n))


class TrajectoryProblem:
    """Stacked cost and equality features: a :class:`~corl.trajectory.solver.LeastSquaresProblem`.

    ``r(w)`` is the concatenation of the cost features (so ``J = r^T r``, Eq. 7) and ``h(w)`` that
    of the equality features; both come with sparse CSR Jacobians (rows in the order given, linear
    features first within each group). Linear features are stacked once at construction.

    Parameters
    ----------
    n : number of parameters (``spline.n``).
    costs : cost features (:class:`LinearFeature` or callables returning ``(phi, dphi/dw)``).
    equalities : equality features, may be empty.
    """

    def __init__(self, n: int, costs: Sequence = (), equalities: Sequence = ()) -> None:
        self.n = int(n)
        if not costs:
            raise InputError("TrajectoryProblem needs at least one cost feature (Eq. 7)")
        self._cost_linear, self._cost_other = self._split(costs, "cost")
        self._eq_linear, self._eq_other = self._split(equalities, "equality")
        self._affine: tuple | None = None
        self._support_layout: _SupportLayout | None | bool = False  # False: not built yet
        self._curvature_layout: tuple | None = None  # equality_curvature's scatter of its blocks
        self._metrics: dict = {}  # distance_problem's cost per metric (shared by with_costs/with_targets copies)

    def _split(self, features: Sequence, what: str) -> tuple[LinearFeature | None, tuple]:
        for f in features:
            if not callable(f):
                raise InputError(f"{what} features must be callables w -> (phi, dphi/dw), got {f!r}")
            A = getattr(f, "A", None)
            if A is not None and A.shape[1] != self.n:
                raise InputError(f"{what} feature {f!r} acts on {A.shape[1]} parameters, expected n = {self.n}")
        linear = [f for f in features if getattr(f, "linear", False)]
        other = tuple(f for f in features if not getattr(f, "linear", False))
        if not linear:
            return None, other
        if len(linear) == 1 and type(linear[0]) is LinearFeature:  # shared as it is (and its cached gram)
            return linear[0], other
        A = stack_csr([f.A for f in linear], self.n)
        return LinearFeature(A, np.concatenate([f.b for f in linear]), name=f"{what}s"), other

    def residuals(self, w: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """``r`` (p,) and ``dr/dw`` (p, n) CSR."""
        return self._evaluate(self._cost_linear, self._cost_other, w)

    def equalities(self, w: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        """``h`` (q,) and ``dh/dw`` (q, n) CSR (q = 0 without equality features)."""
        return self._evaluate(self._eq_linear, self._eq_other, w)

    def _evaluate(self, linear, other, w) -> tuple[np.ndarray, sp.csr_matrix]:
        if not other:
            if linear is None:
                return np.zeros(0), sp.csr_matrix((0, self.n))
            return linear.A @ w - linear.b, linear.A
        parts = [] if linear is None else [linear(w)]
        for f in other:
            value, jac = f(w)
            parts.append((np.asarray(value, dtype=float).ravel(), jac if type(jac) is sp.csr_matrix else sp.csr_matrix(jac)))
        return np.concatenate([p[0] for p in parts]), stack_csr([p[1] for p in parts], self.n)

    def equalities_on_support(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, SupportPattern] | None:
        """``h`` (q,) and ``dh/dw`` kept on the few columns it touches, without a sparse matrix.

        Returns ``(h, support (s,), Js (q, s), pattern)`` with ``Js = dh/dw[:, support]`` and
        ``pattern`` the :class:`~corl.trajectory.solver.banded.SupportPattern` of its structural
        non-zeros (the same object at every w, so the solver caches what it derives from it); or
        None when some nonlinear equality does not offer ``jacobian_rows`` (then use
        :meth:`equalities`). The solver's banded path calls this once per iterate: the layout is
        built on the first call.
        """
        if self._support_layout is False:
            self._support_layout = _SupportLayout.build(self._eq_linear, self._eq_other)
        layout = self._support_layout
        if layout is None:
            return None
        Js = layout.Js_linear.copy()
        values = []
        if self._eq_linear is not None:  # A w - b on the columns the linear rows touch (a small dense product)
            q_linear = self._eq_linear.dim
            values.append(np.dot(Js[:q_linear], w[layout.support]) - self._eq_linear.b)
        for f, rows_at, cols_at in zip(self._eq_other, layout.rows_at, layout.cols_at):
            value, rows = f.jacobian_rows(w)
            values.append(value)
            Js[rows_at, cols_at] = rows
        return np.concatenate(values), layout.support, Js, layout.pattern

    def equality_curvature(self, w: np.ndarray, nu: np.ndarray) -> SupportGram | None:
        """``sum_i nu_i d^2 h_i / dw^2`` (n, n) as a :class:`SupportGram`, or None when every
        equality is linear or offers no ``curvature``; nu: (q,).

        The solver adds it to the Gauss-Newton Hessian (the Lagrangian term that Gauss-Newton
        drops), which turns its steps on a nonlinear contact constraint (Eq. 6) into Newton steps.
        """
        start = 0 if self._eq_linear is None else self._eq_linear.dim
        blocks = []
        for f in self._eq_other:
            stop = start + f.dim
            if hasattr(f, "curvature"):
                blocks.extend(f.curvature(w, nu[start:stop]))
            start = stop
        if not blocks:
            return None
        if len(blocks) == 1:  # one contact time: its columns are already sorted and distinct
            return SupportGram.dense_block(blocks[0][0], blocks[0][1], self.n)
        columns = np.concatenate([cols for cols, _ in blocks])
        layout = self._curvature_layout
        if layout is None or not np.array_equal(layout[0], columns):  # constant per problem: built once
            layout = self._curvature_layout = _curvature_layout(columns, [cols.shape[0] for cols, _ in blocks])
        _, support, flat, pairs = layout
        s = support.shape[0]
        # the blocks summed into G (s, s) in their order (as G[ix_(at, at)] += block, one after the other)
        values = np.concatenate([block.ravel() for _, block in blocks])
        G = np.bincount(flat, values, s * s).reshape(s, s)
        return SupportGram(support, G, self.n, pairs)

    def with_costs(self, costs: Sequence) -> TrajectoryProblem:
        """The same equalities under other cost features (e.g. Eq. 18's ``||L (w - w*)||^2``).

        The equality features, and the layout of their Jacobian on its support, are shared with
        this problem (nothing is rebuilt); only the cost is new.
        """
        if not costs:
            raise InputError("TrajectoryProblem needs at least one cost feature (Eq. 7)")
        other = copy.copy(self)
        other._cost_linear, other._cost_other = self._split(costs, "cost")
        other._affine = None
        return other

    def with_targets(self, targets: Sequence) -> TrajectoryProblem:
        """The same problem with its nonlinear equalities at other targets: ``targets[i]`` for the
        i-th (a :class:`TaskSpaceFeature`, :meth:`TaskSpaceFeature.with_targets`). The cost, the linear
        equalities and the layout of the Jacobian on its support (so the solver's caches on its
        pattern) are shared: a task's Eq. 6 at a new theta without rebuilding it."""
        if len(targets) != len(self._eq_other):
            raise InputError(f"{len(targets)} targets for {len(self._eq_other)} nonlinear equality features")
        if self._support_layout is False:
            self._support_layout = _SupportLayout.build(self._eq_linear, self._eq_other)
        self.affine_cost()  # computed once, shared
        other = copy.copy(self)
        other._eq_other = tuple(f.with_targets(t) for f, t in zip(self._eq_other, targets))
        return other

    def distance_problem(self, w_star: np.ndarray, metric=None) -> TrajectoryProblem:
        """Eq. 18 under these equalities: the cost ``||L (w - w*)||^2``, ``L`` the sparse ``metric``
        (rows, n) or the identity; w_star: (n,). Linear, so the SQP solver takes it on its banded path."""
        keep = metric is None or sp.issparse(metric)  # a task's constant metric: L, its gram and transpose once
        found = self._metrics.get(id(metric)) if keep else None
        if found is None or found[0] is not metric:
            L = sp.identity(self.n, format="csr") if metric is None else sp.csr_matrix(metric, dtype=float)
            if L.shape[1] != self.n:
                raise InputError(f"the metric of Eq. 18 has shape {L.shape}, expected (rows, {self.n})")
            if len(self._metrics) >= 4:
                self._metrics.clear()
            found = (metric, LinearFeature(L, name="distance to w* (Eq. 18)"))
            if keep:
                self._metrics[id(metric)] = found
        distance = found[1]
        return self.with_costs([distance.with_b(distance.A @ np.asarray(w_star, dtype=float))])

    def cost(self, w: np.ndarray) -> float:
        """``J(w) = r^T r`` (Eq. 7)."""
        r, _ = self.residuals(w)
        return float(r @ r)

    def affine_transpose(self) -> sp.csr_matrix | None:
        """``A^T`` (n, p) of an affine cost ``r = A w - b`` (see :meth:`affine_cost`), else None: the
        solver's cost gradient is then ``2 A^T r`` (a CSR product over A's few non-zeros)."""
        if self._cost_other or self._cost_linear is None:
            return None
        return self._cost_linear.transpose()

    def affine_cost(self) -> tuple[BandedSPD, np.ndarray] | None:
        """``(2 A^T A, 2 A^T b)`` when every cost feature is linear (``r = A w - b``), else None.

        The Gauss-Newton Hessian of J in band storage and the constant of its gradient
        ``2 A^T A w - 2 A^T b``: the solver then never forms ``Jr^T Jr`` or ``Jr^T r`` again.
        """
        if self._cost_other or self._cost_linear is None:
            return None
        if self._affine is None:
            A, b = self._cost_linear.A, self._cost_linear.b
            H = self._cost_linear.gram()
            c = 2.0 * (A.T @ b)
            if not (np.all(np.isfinite(H.ab)) and np.all(np.isfinite(c))):
                raise NumericalError("the linear cost features contain NaN or inf")
            self._affine = (H, c)
        return self._affine


def _curvature_layout(columns: np.ndarray, sizes: list[int]) -> tuple:
    """``(columns, support (s,), flat, pairs)`` for blocks on the concatenated ``columns`` (sum of
    ``sizes``): ``flat`` the positions of the blocks' entries in ``G.ravel()`` (G: (s, s)), ``pairs``
    the lower-triangle entries some block touches (the structural pattern of their sum)."""
    support = np.unique(columns)
    s = support.shape[0]
    flat, touched, start = [], np.zeros((s, s), dtype=bool), 0
    for size in sizes:
        at = np.searchsorted(support, columns[start : start + size])
        flat.append((at[:, None] * s + at[None, :]).ravel())
        touched[np.ix_(at, at)] = True
        start += size
    return columns, support, np.concatenate(flat), np.nonzero(np.tril(touched))


class _SupportLayout:
    """Where the rows of the stacked equality Jacobian go in its dense block ``Js`` (q, s) on the
    touched columns ``support`` (s,): constant, since the linear rows are constant and each
    :class:`TaskSpaceFeature` row touches the same ``(degree + 1) Q`` columns at every w.
    ``pattern`` is its :class:`~corl.trajectory.solver.banded.SupportPattern`."""

    __slots__ = ("support", "Js_linear", "rows_at", "cols_at", "pattern")

    def __init__(self, support, Js_linear, rows_at, cols_at, pattern) -> None:
        self.support, self.Js_linear, self.rows_at, self.cols_at, self.pattern = support, Js_linear, rows_at, cols_at, pattern

    @classmethod
    def build(cls, linear: LinearFeature | None, other: tuple) -> _SupportLayout | None:
        """The layout, or None when a nonlinear equality has no ``jacobian_rows``/``columns``."""
        if not other or not all(hasattr(f, "jacobian_rows") and hasattr(f, "columns") for f in other):
            return None
        A = sp.csr_matrix((0, 0)) if linear is None else linear.A
        support = np.unique(np.concatenate([A.indices.astype(np.int64)] + [f.columns.ravel() for f in other]))
        q = A.shape[0] + sum(f.dim for f in other)
        Js_linear = np.zeros((q, support.shape[0]))
        touched = np.zeros((q, support.shape[0]), dtype=bool)
        if linear is not None:
            Js_linear[: A.shape[0]] = A[:, support].toarray()
            touched[: A.shape[0]] = Js_linear[: A.shape[0]] != 0.0
        rows_at, cols_at = [], []
        start = A.shape[0]
        for f in other:
            rows = np.arange(start, start + f.dim)[:, None]
            cols = np.searchsorted(support, f.columns)
            touched[rows, cols] = True
            rows_at.append(rows)
            cols_at.append(cols)
            start += f.dim
        return cls(support, Js_linear, tuple(rows_at), tuple(cols_at), SupportPattern(support, touched))
