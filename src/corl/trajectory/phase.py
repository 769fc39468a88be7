"""Phase-profile optimization with fixed geometry (Sec. VI-B, Eq. 10) and the re-fit of a re-timed path.

The path of ``xi(w, .)`` is kept and only its timing changes: the re-timed trajectory is
``xi(w, p(t) T)`` for a phase profile ``p: [0, T] -> [0, 1]`` discretized at ``t_i = i dt``,
``dt = T / K``, as ``p_0 = 0 < p_1 < ... < p_K = 1``. Eq. 10::

    J(p) = sum_i ((xi(w, p_{i-1} T) - 2 xi(w, p_i T) + xi(w, p_{i+1} T)) / dt^2)^2
         + c_p (p_{i-1} - 2 p_i + p_{i+1})^2                        (c_p = 1 in the paper)

is minimised over the interior phases by :func:`corl.trajectory.solver.solve` (Gauss-Newton,
trust region ``||p - p_prev|| <= radius``, as Eq. 8 limits w). Every residual touches at most three
consecutive phases, so :class:`PhaseProblem` gives its Gauss-Newton model ``2 Jr^T Jr`` in band
storage (bandwidth 2, :meth:`PhaseProblem.gauss_newton_band`) and the damped Gauss-Newton steps run
on banded Cholesky factors, with no sparse Jacobian built per iterate. Monotonicity
``p_{i+1} - p_i >= delta`` is a squared-hinge penalty ``c_m max(0, delta - (p_{i+1} - p_i))^2 /
dt^4`` in the same least-squares problem; should a tiny violation survive, a final repair raises
each increment to ``delta / 2`` (renormalised so ``p_K = 1``), so the returned p is always
strictly increasing. Phases at ``pinned_times`` (contact times) can be held at ``t / T`` so a
contact stays where Eq. 6 puts it.

:func:`retime` turns an optimal profile into new parameters: it samples the re-timed path and
re-fits the B-spline control points by least squares, then (given the equalities) projects onto
``h = 0`` with Eq. 18 and reports how much h changed.

The schedule of Sec. VIII-B - trajectory steps (Eq. 8) until w stops moving, then phase steps,
each rolled out - is Algorithm 1's step 1 and lives in one place, :class:`corl.learner.CORL`.

Glossary
--------
w, n       : trajectory parameters (n,), time-major (``w.reshape(P, Q)``)
T, K, dt   : duration, number of phase intervals, ``T / K``
p          : phase profile (K+1,), p_0 = 0, p_K = 1; ``p = t / T`` is the identity (no re-timing)
free       : indices of the optimised interior phases (not 0, K or pinned)
delta      : smallest allowed phase increment
c_p, c_m   : weights of the phase-acceleration term (Eq. 10) and of the monotonicity hinge
h          : equality constraints of the trajectory problem (Eq. 6), reported around re-fits
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline as _ScipyBSpline

from corl.errors import InputError
from corl.trajectory.bspline import BSpline
from corl.trajectory.solver import SolveResult, SolverConfig, project, solve
from corl.trajectory.solver.banded import BandedSPD

__all__ = [
    "PhaseConfig",
    "PhaseResult",
    "RetimeResult",
    "PhaseProblem",
    "phase_cost",
    "optimize_phase",
    "retime",
]


@dataclass(frozen=True)
class PhaseConfig:
    """Settings of the phase optimization (Eq. 10).

    Attributes
    ----------
    num_steps : K, phase intervals (K + 1 phases).
    phase_weight : c_p, weight of the squared phase accelerations (1 in Eq. 10).
    min_increment : delta as a fraction of the uniform increment 1 / K (0 < . < 1).
    monotone_weight : c_m, weight of the squared-hinge monotonicity penalty (scaled by 1 / dt^4
        like the configuration accelerations).
    radius : trust region on the phase step, ``||p - p_prev|| <= radius`` (the eps_max of Eq. 8).
    fit_samples_per_point : samples of the re-timed path per control point for the re-fit.
    solver : settings of the inner Gauss-Newton solve.
    """

    num_steps: int = 100
    phase_weight: float = 1.0
    min_increment: float = 0.05
    monotone_weight: float = 1e4
    radius: float = 0.05
    fit_samples_per_point: int = 4
    solver: SolverConfig = field(default_factory=lambda: SolverConfig(tol_step=1e-9, max_iterations=100))

    def __post_init__(self) -> None:
        if not isinstance(self.num_steps, (int, np.integer)) or self.num_steps < 2:
            raise InputError(f"PhaseConfig.num_steps must be an integer >= 2, got {self.num_steps!r}")
        for name in ("phase_weight", "monotone_weight", "radius"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise InputError(f"PhaseConfig.{name} must be a finite number >= 0, got {value!r}")
        if not self.radius > 0:
            raise InputError(f"PhaseConfig.radius must be positive, got {self.radius!r}")
        if not (0 < self.min_increment < 1):
            raise InputError(f"PhaseConfig.min_increment must be in (0, 1) (a fraction of 1/K), got {self.min_increment!r}")
        if not isinstance(self.fit_samples_per_point, (int, np.integer)) or self.fit_samples_per_point < 2:
            raise InputError(f"PhaseConfig.fit_samples_per_point must be an integer >= 2, got {self.fit_samples_per_point!r}")


# ---------------------------------------------------------------------------------------------
# Eq. 10 as a least-squares problem over the interior phases
# ---------------------------------------------------------------------------------------------
class PhaseProblem:
    """Eq. 10 plus the monotonicity hinge, as a :class:`~corl.trajectory.solver.LeastSquaresProblem`
    over the free phases ``p[free]``.

    Each residual touches at most three consecutive phases, so ``Jr^T Jr`` is banded (bandwidth 2):
    :meth:`gauss_newton_band` gives the Gauss-Newton model in band storage, and the solver's damped
    Gauss-Newton steps run on banded Cholesky factors with no sparse matrix built per iterate.

    Parameters
    ----------
    spline, w : the trajectory whose geometry is kept; w: (n,).
    config : :class:`PhaseConfig`.
    pinned_times : times in (0, T) whose phase stays ``t / T`` (the nearest grid phase is pinned).
    """

    def __init__(self, spline: BSpline, w, config: PhaseConfig, pinned_times: Sequence[float] = ()) -> None:
        self.spline, self.config = spline, config
        self.W = spline.control_points(w)
        K = config.num_steps
        self.K, self.T = K, float(spline.duration)
        self.dt = self.T / K
        self.delta = config.min_increment / K
        fixed = {0, K} | {int(round(float(t) / self.dt)) for t in np.atleast_1d(np.asarray(pinned_times, dtype=float))}
        self.fixed = np.array(sorted(i for i in fixed if 0 <= i <= K))
        self.free = np.setdiff1d(np.arange(K + 1), self.fixed)
        if self.free.size == 0:
            raise InputError("every phase is pinned; nothing to optimize (fewer pinned_times or more num_steps)")
        self.identity = np.linspace(0.0, 1.0, K + 1)
        D2 = sp.diags((1.0, -2.0, 1.0), (0, 1, 2), shape=(K - 1, K + 1), format="csr")  # rows i = 1..K-1
        D1 = sp.diags((-1.0, 1.0), (0, 1), shape=(K, K + 1), format="csr")  # p_{i+1} - p_i, i = 0..K-1
        self.D2, self.D1 = D2, D1
        self.D2_x = sp.kron(D2, sp.identity(spline.num_joints), format="csr") / self.dt**2
        self.phase_rows = math.sqrt(config.phase_weight) * D2
        self.hinge_scale = math.sqrt(config.monotone_weight) / self.dt**2
        # xi(w, .) and its time derivative as spline objects (de Boor evaluation, no basis matrix)
        self._xi = _ScipyBSpline(spline.knots, self.W, spline.degree)
        self._dxi = self._xi.derivative(1)
        self._band_free = _free_band_positions(self.free, K)
        c = config.phase_weight  # (sqrt(c_p) D2)^T (sqrt(c_p) D2): a constant part of the band
        self._phase_band = _second_difference_band(np.full(K + 1, c), np.full(K, c), np.full(K - 1, c))

    def full(self, p_free: np.ndarray) -> np.ndarray:
        """The whole profile (K+1,) from the free phases (fixed ones at ``t / T``)."""
        p = self.identity.copy()
        p[self.free] = p_free
        return p

    def _pieces(self, p_free: np.ndarray) -> tuple:
        """``(p (K+1,), U (K+1, Q), r_x (K-1, Q), r_p (K-1,), active (K,), r_m (K,))`` at p_free, with
        ``U = T xi'(p T) / dt^2`` (so ``d r_x[i] / dp_j = U[j]`` times the stencil (1, -2, 1))."""
        p = self.full(p_free)
        s = np.clip(p, 0.0, 1.0) * self.T
        X = self._xi(s)  # xi(w, p_i T): (K+1, Q)
        U = (self.T / self.dt**2) * self._dxi(s)
        # Eq. 10, first term: (xi(p_{i-1} T) - 2 xi(p_i T) + xi(p_{i+1} T)) / dt^2
        r_x = (X[:-2] - 2.0 * X[1:-1] + X[2:]) / self.dt**2
        # Eq. 10, second term: c_p (p_{i-1} - 2 p_i + p_{i+1})^2
        r_p = math.sqrt(self.config.phase_weight) * (p[:-2] - 2.0 * p[1:-1] + p[2:])
        # Monotonicity: c_m max(0, delta - (p_{i+1} - p_i))^2 / dt^4 (squared hinge)
        gap = np.diff(p)
        active = (gap < self.delta).astype(float)
        r_m = self.hinge_scale * active * (self.delta - gap)
        return p, U, r_x, r_p, active, r_m

    def residuals(self, p_free: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        p, U, r_x, r_p, active, r_m = self._pieces(p_free)
        K, Q = self.K, U.shape[1]
        # d r_x[i, j] / dp_m = U[m, j] (1, -2, 1)[m - i + 1]: the rows of D2_x times diag(U)
        dX = sp.csr_matrix(
            (U.reshape(-1) * self.dt**2, np.repeat(np.arange(K + 1), Q), np.arange((K + 1) * Q + 1)),
            shape=((K + 1) * Q, K + 1),
        )
        J_x = self.D2_x @ dX
        J_m = sp.diags(-self.hinge_scale * active) @ self.D1
        r = np.concatenate([r_x.reshape(-1), r_p, r_m])
        J = sp.vstack([J_x, self.phase_rows, J_m], format="csc")[:, self.free]
        return r, J.tocsr()

    def gauss_newton_band(self, p_free: np.ndarray) -> tuple[np.ndarray, np.ndarray, BandedSPD]:
        """``(r, 2 Jr^T r (f,), 2 Jr^T Jr)`` at p_free (f,), the last in band storage (bandwidth 2).

        The Gram of the rows ``(1, -2, 1)`` on phases ``(i-1, i, i+1)`` with weights U (Eq. 10) and
        of the hinge rows on ``(m, m+1)``, summed on the whole profile and restricted to the free
        phases (:func:`_free_band_positions`).
        """
        p, U, r_x, r_p, active, r_m = self._pieces(p_free)
        # Eq. 10, first term: U[m] . U[m + o] for o = 0, 1, 2
        d0 = np.einsum("ij,ij->i", U, U)
        d1 = np.einsum("ij,ij->i", U[:-1], U[1:])
        d2 = np.einsum("ij,ij->i", U[:-2], U[2:])
        band = _second_difference_band(d0, d1, d2) + self._phase_band
        a = self.hinge_scale**2 * active  # hinge rows: a [[1, -1], [-1, 1]] on (m, m+1)
        band[0, :-1] += a
        band[0, 1:] += a
        band[1, :-1] -= a
        # J^T r: stencil (1, -2, 1) times the per-phase products U . r_x (and c_p r_p), hinge (1, -1)
        c = math.sqrt(self.config.phase_weight)
        g = np.zeros(self.K + 1)
        g[:-2] += np.einsum("ij,ij->i", U[:-2], r_x) + c * r_p
        g[1:-1] -= 2.0 * (np.einsum("ij,ij->i", U[1:-1], r_x) + c * r_p)
        g[2:] += np.einsum("ij,ij->i", U[2:], r_x) + c * r_p
        e = self.hinge_scale * r_m  # active rows only (r_m is 0 elsewhere)
        g[:-1] += e
        g[1:] -= e
        flat = np.append(band.reshape(-1), 0.0)  # the last entry: a zero for pairs beyond the band
        ab = np.asfortranarray(2.0 * flat[self._band_free])
        r = np.concatenate([r_x.reshape(-1), r_p, r_m])
        return r, 2.0 * g[self.free], BandedSPD(ab)

    def equalities(self, p_free: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0), np.zeros((0, p_free.shape[0]))

    def eq10(self, p: np.ndarray) -> float:
        """Eq. 10 (without the hinge) for a whole profile p (K+1,)."""
        X = self._xi(np.clip(p, 0.0, 1.0) * self.T)
        r_x = (X[:-2] - 2.0 * X[1:-1] + X[2:]) / self.dt**2
        r_p = self.phase_rows @ p
        return float(np.dot(r_x.reshape(-1), r_x.reshape(-1)) + r_p @ r_p)


def _second_difference_band(d0: np.ndarray, d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Lower band (3, K+1) of ``sum_i s_i^T s_i`` over the rows ``s_i = (u_{i-1}, -2 u_i, u_{i+1})``
    on phases ``(i-1, i, i+1)``, i = 1..K-1, given ``d_o[m] = u_m . u_{m+o}``: (K+1,), (K,), (K-1,)."""
    K = d0.shape[0] - 1
    band = np.zeros((3, K + 1))
    band[0, :-2] += d0[:-2]  # (i-1, i-1)
    band[0, 1:-1] += 4.0 * d0[1:-1]  # (i, i)
    band[0, 2:] += d0[2:]  # (i+1, i+1)
    band[1, :-2] -= 2.0 * d1[:-1]  # (i, i-1), stored in column i-1
    band[1, 1:-1] -= 2.0 * d1[1:]  # (i+1, i), stored in column i
    band[2, :-2] += d2  # (i+1, i-1)
    return band


def _free_band_positions(free: np.ndarray, K: int) -> np.ndarray:
    """Flat positions (3, f) in a C-ordered band (3, K+1) of the free phases' band entries: entry
    (o, j) of the free band is ``H[free[j + o], free[j]]``, at offset ``free[j + o] - free[j]`` of the
    whole profile; pairs beyond offset 2 (or past the end) point at ``3 (K+1)``, a zero."""
    f = free.shape[0]
    positions = np.full((3, f), 3 * (K + 1), dtype=np.intp)
    for o in range(3):
        j = np.arange(f - o)
        offset = free[j + o] - free[j]
        inside = offset <= 2
        positions[o, j[inside]] = offset[inside] * (K + 1) + free[j[inside]]
    return positions


def phase_cost(spline: BSpline, w, p, config: PhaseConfig = PhaseConfig()) -> float:
    """Eq. 10 for the profile p (K+1,) with ``K = config.num_steps``."""
    p = np.asarray(p, dtype=float)
    if p.shape != (config.num_steps + 1,):
        raise InputError(f"p has shape {p.shape}, expected ({config.num_steps + 1},) = num_steps + 1")
    return PhaseProblem(spline, w, config).eq10(p)


@dataclass(frozen=True)
class PhaseResult:
    """Outcome of :func:`optimize_phase`.

    Attributes
    ----------
    p : (K+1,) the new profile: p_0 = 0, p_K = 1, strictly increasing.
    cost_before, cost_after : Eq. 10 at the start profile and at p.
    step_norm : ``||p - p_start||``.
    repaired : True when the final monotonicity repair changed p.
    solve : the inner :class:`~corl.trajectory.solver.SolveResult` (history per Gauss-Newton step).
    """

    p: np.ndarray
    cost_before: float
    cost_after: float
    step_norm: float
    repaired: bool
    solve: SolveResult


def optimize_phase(
    spline: BSpline,
    w,
    p_start=None,
    *,
    config: PhaseConfig = PhaseConfig(),
    pinned_times: Sequence[float] = (),
) -> PhaseResult:
    """One phase step: minimise Eq. 10 over p inside ``||p - p_start|| <= config.radius``.

    Parameters
    ----------
    spline, w : the trajectory (geometry kept); w: (n,).
    p_start : (K+1,) start and trust-region center; default the identity ``t / T``.
    config : :class:`PhaseConfig`.
    pinned_times : times whose phase stays ``t / T`` (e.g. contact times of Eq. 6).
    """
    problem = PhaseProblem(spline, w, config, pinned_times)
    p0 = problem.identity if p_start is None else np.asarray(p_start, dtype=float)
    if p0.shape != (config.num_steps + 1,) or abs(p0[0]) > 1e-12 or abs(p0[-1] - 1.0) > 1e-12:
        raise InputError(f"p_start must have shape ({config.num_steps + 1},) with p_0 = 0 and p_K = 1")
    result = solve(problem, p0[problem.free], radius=config.radius, config=config.solver)
    p = problem.full(result.w)
    p[problem.fixed] = p0[problem.fixed]
    p, repaired = _monotone(p, problem.delta)
    return PhaseResult(
        p=p,
        cost_before=problem.eq10(p0),
        cost_after=problem.eq10(p),
        step_norm=float(np.linalg.norm(p - p0)),
        repaired=repaired,
        solve=result,
    )


def _monotone(p: np.ndarray, delta: float) -> tuple[np.ndarray, bool]:
    """Raise every increment of p (K+1,) below ``delta / 2`` to it, keeping p_0 = 0 and p_K = 1."""
    gaps = np.diff(p)
    floor = 0.5 * delta
    if np.all(gaps >= floor):
        return p, False
    gaps = np.maximum(gaps, floor)
    excess = gaps - floor  # take the added length back from the increments above the floor
    gaps = floor + excess * ((1.0 - floor * gaps.shape[0]) / excess.sum())
    return np.concatenate([[0.0], np.cumsum(gaps)[:-1], [1.0]]), True


# ---------------------------------------------------------------------------------------------
# Re-timing: new control points for xi(w, p(t) T)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RetimeResult:
    """Outcome of :func:`retime`.

    Attributes
    ----------
    w : (n,) parameters of the re-timed trajectory (projected onto h = 0 when equalities were given).
    w_fit : (n,) the least-squares fit before the projection.
    fit_error : max distance between the fitted spline and the re-timed samples.
    h_before : ``max |h|`` of the original w; ``h_fit`` of w_fit; ``h_after`` of w (nan without equalities).
    projection : the Eq. 18 result, or None.
    """

    w: np.ndarray
    w_fit: np.ndarray
    fit_error: float
    h_before: float
    h_fit: float
    h_after: float
    projection: SolveResult | None


def retime(spline: BSpline, w, p, *, equalities=None, config: PhaseConfig = PhaseConfig()) -> RetimeResult:
    """Control points of the re-timed path ``xi(w, p(t) T)`` (p linear between grid phases).

    Samples the re-timed path at ``fit_samples_per_point * P`` times, fits the B-spline by least
    squares (:meth:`BSpline.fit`), and, when ``equalities`` (a callable ``w -> (h, dh/dw)`` or a
    problem) are given, projects the fit onto ``h = 0`` (Eq. 18, :func:`~corl.trajectory.solver.project`)
    so the contacts still hold: by SQP for a :class:`~corl.trajectory.features.TrajectoryProblem`,
    along the constraint manifold for a callable.
    """
    p = np.asarray(p, dtype=float)
    K = p.shape[0] - 1
    T = float(spline.duration)
    times = np.linspace(0.0, T, config.fit_samples_per_point * spline.num_control_points)
    phases = np.interp(times, np.linspace(0.0, T, K + 1), p)
    samples = spline.positions(w, np.clip(phases, 0.0, 1.0) * T)
    w_fit = spline.fit(times, samples)
    fit_error = float(np.abs(spline.positions(w_fit, times) - samples).max())
    nan = float("nan")
    if equalities is None:
        return RetimeResult(w_fit, w_fit, fit_error, nan, nan, nan, None)
    fn = getattr(equalities, "equalities", equalities)
    h_before = float(np.abs(fn(np.asarray(w, dtype=float))[0]).max(initial=0.0))
    h_fit = float(np.abs(fn(w_fit)[0]).max(initial=0.0))
    projection = project(equalities, w_fit, config=SolverConfig.trajectory())  # SQP for a TrajectoryProblem
    return RetimeResult(projection.w, w_fit, fit_error, h_before, h_fit, projection.constraint_error, projection)
