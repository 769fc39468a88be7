"""B-spline reference trajectories ``xi(w, t) = B(t) w`` (Sec. V-A).

The policy's reference is a clamped (open uniform) B-spline of degree ``k`` on ``[0, T]`` with P
control points in a Q-dimensional configuration space, so ``n = P Q`` parameters. The layout of w
is time-major: ``w.reshape(P, Q)[p]`` is control point p, so ``w[p * Q + j]`` is joint j of control
point p. With this layout every k-order Markov feature (Eq. 7) touches a contiguous block of w, and
the Gauss-Newton matrix of Eq. 8 is banded (:mod:`corl.trajectory.solver.banded`).

Derivatives use the derivative spline: the d-th derivative of a degree-k spline on knots ``t`` is a
spline of degree ``k - d`` on ``t[d:-d]`` whose control points are scaled differences of the
original ones (de Boor, A Practical Guide to Splines, Ch. X), so ``B^(d)(t) = N_{k-d}(t) D_d ... D_1``.

Glossary
--------
P, Q      : number of control points and of joints; n = P Q
k         : degree (3: cubic); the trajectory is C^(k-1)
T         : duration; times live in [0, T]
knots     : clamped knot vector (P + k + 1,): k + 1 zeros, P - k - 1 uniform interior knots, k + 1 T's
W         : control points w.reshape(P, Q)
B(times)  : basis matrix (K+1, P), sparse: row i holds the k + 1 basis values at times[i]
operator  : ``kron(B, I_Q)`` ((K+1) Q, n), sparse: ``operator @ w`` is xi at the times, flattened time-major
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.interpolate import BSpline as _ScipyBSpline

from corl.errors import InputError
from corl.trajectory.solver.banded import BandedSPD, banded_cholesky

__all__ = ["BSpline"]

_TIME_SLACK = 1e-9  # relative slack on [0, T] for times that rounding pushed just outside


@dataclass(frozen=True)
class BSpline:
    """A clamped uniform B-spline trajectory basis with P control points in Q dimensions (Sec. V-A).

    Attributes
    ----------
    num_control_points : P, at least ``degree + 1``.
    num_joints : Q, at least 1.
    duration : T > 0; the trajectory is defined on [0, T].
    degree : k >= 1 (3, cubic, by default).

    Examples
    --------
    >>> spline = BSpline(num_control_points=150, num_joints=7, duration=5.0)
    >>> spline.n
    1050
    """

    num_control_points: int
    num_joints: int
    duration: float = 1.0
    degree: int = 3

    def __post_init__(self) -> None:
        for name in ("num_control_points", "num_joints", "degree"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
                raise InputError(f"BSpline.{name} must be an integer, got {value!r}")
        if self.degree < 1:
            raise InputError(f"BSpline.degree must be >= 1, got {self.degree}")
        if self.num_joints < 1:
            raise InputError(f"BSpline.num_joints must be >= 1, got {self.num_joints}")
        if self.num_control_points < self.degree + 1:
            raise InputError(
                f"BSpline.num_control_points = {self.num_control_points} is too small for degree "
                f"{self.degree}; a clamped spline needs at least degree + 1 = {self.degree + 1}"
            )
        if not (isinstance(self.duration, (int, float)) and math.isfinite(self.duration) and self.duration > 0):
            raise InputError(f"BSpline.duration must be a positive finite number, got {self.duration!r}")

    # -- structure --------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of parameters ``P Q``."""
        return self.num_control_points * self.num_joints

    @cached_property
    def knots(self) -> np.ndarray:
        """Clamped uniform knot vector (P + k + 1,) on [0, T]."""
        k, P, T = self.degree, self.num_control_points, float(self.duration)
        interior = np.linspace(0.0, T, P - k + 1)[1:-1]
        return np.concatenate([np.zeros(k + 1), interior, np.full(k + 1, T)])

    @cached_property
    def _difference_chain(self) -> tuple:
        """``(D_1, D_2, ...)``: D_d (P - d, P - d + 1) maps the control points of derivative d - 1
        to those of derivative d (degree k - d + 1 spline on ``knots[d-1 : len - d + 1]``)."""
        chain = []
        t, k = self.knots, self.degree
        for d in range(1, k + 1):
            m = self.num_control_points - d  # control points of the derivative spline
            deg = k - d + 1  # degree of the spline being differentiated
            sub = t[d - 1 : len(t) - d + 1]
            i = np.arange(m)
            scale = deg / (sub[i + deg + 1] - sub[i + 1])  # positive for clamped knots
            D = sp.csr_matrix(
                (np.concatenate([-scale, scale]), (np.concatenate([i, i]), np.concatenate([i, i + 1]))),
                shape=(m, m + 1),
            )
            chain.append(D)
        return tuple(chain)

    def control_points(self, w) -> np.ndarray:
        """``w.reshape(P, Q)`` after checking the length; w: (n,) -> W: (P, Q)."""
        w = np.asarray(w, dtype=float)
        if w.shape != (self.n,):
            raise InputError(
                f"w has shape {w.shape}, expected ({self.n},) = P * Q = "
                f"{self.num_control_points} * {self.num_joints} (time-major: w.reshape(P, Q))"
            )
        return w.reshape(self.num_control_points, self.num_joints)

    def _times(self, times) -> np.ndarray:
        t = np.atleast_1d(np.asarray(times, dtype=float))
        if t.ndim != 1:
            raise InputError(f"times must be a scalar or a vector, got shape {t.shape}")
        T = float(self.duration)
        slack = _TIME_SLACK * T
        if t.size and (not np.all(np.isfinite(t)) or t.min() < -slack or t.max() > T + slack):
            raise InputError(f"times must lie in [0, T] = [0, {T:g}], got values in [{t.min():g}, {t.max():g}]")
        return np.clip(t, 0.0, T)

    # -- basis matrices ---------------------------------------------------------------------------
    def basis(self, times, derivative: int = 0) -> sp.csr_matrix:
        """Basis matrix ``B^(d)(times)`` (K+1, P), sparse CSR, of the ``derivative``-th time derivative.

        Parameters
        ----------
        times : (K+1,) times in [0, T] (any order, repeats allowed), or a scalar.
        derivative : d >= 0; rows are zero for d > degree.
        """
        if not isinstance(derivative, (int, np.integer)) or derivative < 0:
            raise InputError(f"derivative must be an integer >= 0, got {derivative!r}")
        t = self._times(times)
        k, P = self.degree, self.num_control_points
        if derivative > k:
            return sp.csr_matrix((t.shape[0], P))
        knots = self.knots[derivative : len(self.knots) - derivative] if derivative else self.knots
        N = _ScipyBSpline.design_matrix(t, knots, k - derivative)
        B = sp.csr_matrix(N)
        for D in reversed(self._difference_chain[:derivative]):
            B = B @ D  # N_{k-d} D_d ... D_1
        return sp.csr_matrix(B)

    def operator(self, times, derivative: int = 0) -> sp.csr_matrix:
        """``kron(B^(d)(times), I_Q)`` ((K+1) Q, n): ``operator @ w`` is ``xi^(d)`` at the times, flattened
        time-major (reshape to (K+1, Q))."""
        return sp.kron(self.basis(times, derivative), sp.identity(self.num_joints, format="csr"), format="csr")

    # -- evaluation -------------------------------------------------------------------------------
    def evaluate(self, w, times, derivative: int = 0) -> np.ndarray:
        """``xi^(d)(w, times)`` (K+1, Q); w: (n,), times: (K+1,) or scalar."""
        return self.basis(times, derivative) @ self.control_points(w)

    def positions(self, w, times) -> np.ndarray:
        """``xi(w, times)`` (K+1, Q)."""
        return self.evaluate(w, times, 0)

    def velocities(self, w, times) -> np.ndarray:
        """``d xi / dt`` at the times, (K+1, Q)."""
        return self.evaluate(w, times, 1)

    def accelerations(self, w, times) -> np.ndarray:
        """``d^2 xi / dt^2`` at the times, (K+1, Q)."""
        return self.evaluate(w, times, 2)

    def grid(self, num_steps: int) -> np.ndarray:
        """The K + 1 equidistant times ``t dt``, ``dt = T / K``, of Eq. 9; (K+1,)."""
        if not isinstance(num_steps, (int, np.integer)) or num_steps < 1:
            raise InputError(f"num_steps must be an integer >= 1, got {num_steps!r}")
        return np.linspace(0.0, float(self.duration), num_steps + 1)

    # -- fitting ----------------------------------------------------------------------------------
    def fit(self, times, samples, *, regularization: float = 0.0) -> np.ndarray:
        """Least-squares control points of a sampled trajectory (a demonstration -> w0).

        ``argmin_W ||B(times) W - samples||^2 + regularization ||W||^2``, solved by a banded
        Cholesky of ``B^T B`` (P, P), whose bandwidth is the degree.

        Parameters
        ----------
        times : (K+1,) sample times in [0, T].
        samples : (K+1, Q) configurations at those times.
        regularization : >= 0; needed only when some knot span holds too few samples.

        Returns
        -------
        w : (n,) time-major parameters (``w.reshape(P, Q)`` are the control points).
        """
        t = self._times(times)
        X = np.asarray(samples, dtype=float)
        if X.ndim == 1 and self.num_joints == 1:
            X = X[:, None]
        if X.shape != (t.shape[0], self.num_joints):
            raise InputError(f"samples have shape {X.shape}, expected ({t.shape[0]}, {self.num_joints}) for these times")
        if not np.all(np.isfinite(X)):
            raise InputError("samples contain NaN or inf")
        if not (math.isfinite(regularization) and regularization >= 0):
            raise InputError(f"regularization must be >= 0, got {regularization!r}")
        B = self.basis(t)
        gram = BandedSPD.from_sparse(B.T @ B, self.degree)
        factor = banded_cholesky(gram.ab, regularization, what="B^T B of the fit")
        if factor.jitter > 0.0 and regularization == 0.0:  # B^T B singular: the fit is not unique
            raise InputError(
                f"cannot fit {self.num_control_points} control points to {t.shape[0]} samples: every "
                "knot span needs samples (Schoenberg-Whitney); pass more samples or regularization > 0"
            )
        W = factor.solve(np.asarray(B.T @ X))
        return W.reshape(-1)
