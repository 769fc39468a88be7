"""Discrete dynamic movement primitives, the policy of the DMP + PoWER baseline (Sec. VIII-B).

The paper's baseline follows Kober & Peters (2011): a DMP per joint, learned from the
demonstration, whose shape weights and goals (Q (N + 1) = 8 * 12 = 96 numbers for the door) are
then improved by PoWER. We use the formulation of Hoffmann, Pastor, Park & Schaal (ICRA 2009),
also given in Ijspeert et al. (Neural Computation 25, 2013, Sec. 2.1.3), per dimension::

    tau dz = K (g - y) - D z - K (g - y0) x + K f(x)        (transformation system)
    tau dy = z
    tau dx = -alpha_x x                                      (canonical system)
    f(x)   = sum_i psi_i(x) w_i x / sum_i psi_i(x),   psi_i(x) = exp(-h_i (x - c_i)^2)

with ``K = alpha_z beta_z`` and ``D = alpha_z``. Unlike the original ``f(x) (g - y0)`` scaling it
does not lose the shape when ``g == y0`` (a gripper that closes and opens again, a joint that
moves out and back), it starts without an acceleration jump, and a change of goal does not
mirror or stretch the shape: the response is linear in ``(w, g)``, so moving the goal by ``d``
adds ``d s(t)`` to the motion, with ``s`` the monotone zero-forcing point-to-point profile. The
forcing term and the weights are in units of position (a shift of the attractor).

The canonical system is solved in closed form, ``x(t) = exp(-alpha_x t / tau)``; the linear
transformation system is integrated by classical Runge-Kutta (RK4), vectorised over the Q
dimensions, with sub-steps short enough for its time constant ``tau / sqrt(K)``.

Glossary
--------
Q        : number of dimensions (8 for the door: 7 arm joints + gripper width)
N        : number of basis functions per dimension (``n_basis``)
y, dy    : position and velocity of the motion, (Q,) per time; z = tau dy
y0, g    : start and goal, (Q,)
x        : phase of the canonical system, 1 at t = 0, decaying to ``exp(-alpha_x)`` at t = tau
tau      : temporal scaling, the duration of the demonstration; rolling out with a larger tau
           is slower
c_i, h_i : centers (N,) and widths (N,) of the Gaussian basis functions in phase space
W        : shape weights (Q, N); ``f`` of dimension q uses ``W[q]``
params   : the learnable vector (Q (N + 1),), dimension-major: ``params.reshape(Q, N + 1)[q]``
           is ``(W[q, 0], ..., W[q, N-1], g[q])``
amplitude: (Q,) range of the demonstration per dimension (floored), the unit of ``param_scale``
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from corl.errors import InputError

__all__ = ["DMP", "DMPConfig", "DEFAULT_DMP_CONFIG", "basis_functions", "phase", "forcing_features"]

_MAX_STEP_RATE = 0.25  # RK4 sub-step h: h sqrt(K) / tau <= this (stable and accurate for dt-level output)
_AMPLITUDE_FLOOR = 0.05  # amplitudes below this fraction of the largest one are raised to it


def _positive(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InputError(f"{name} must be a number, got {value!r}")
    if not (math.isfinite(value) and value > 0.0):
        raise InputError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class DMPConfig:
    """Gains and basis layout of a :class:`DMP`.

    Attributes
    ----------
    alpha_z : damping D of the transformation system (25, Ijspeert et al. 2013).
    beta_z : stiffness factor, ``K = alpha_z beta_z``; ``alpha_z / 4`` is critically damped.
    alpha_x : decay of the canonical system; ``ln 100`` lets the phase fall to 1 % at t = tau.
    overlap : height in (0, 1) at which neighbouring basis functions cross, halfway between
        their centers (0.5).
    ridge : Tikhonov factor of the least-squares fit, relative to the mean diagonal of the
        normal matrix; keeps weights of basis functions with little data bounded.
    """

    alpha_z: float = 25.0
    beta_z: float = 25.0 / 4.0
    alpha_x: float = math.log(100.0)
    overlap: float = 0.5
    ridge: float = 1e-8

    def __post_init__(self) -> None:
        for name in ("alpha_z", "beta_z", "alpha_x"):
            object.__setattr__(self, name, _positive(f"DMPConfig.{name}", getattr(self, name)))
        if not (isinstance(self.overlap, (int, float)) and 0.0 < self.overlap < 1.0):
            raise InputError(f"DMPConfig.overlap must lie in (0, 1), got {self.overlap!r}")
        if not (isinstance(self.ridge, (int, float)) and math.isfinite(self.ridge) and self.ridge >= 0.0):
            raise InputError(f"DMPConfig.ridge must be a finite number >= 0, got {self.ridge!r}")

    @property
    def stiffness(self) -> float:
        """K = alpha_z beta_z."""
        return self.alpha_z * self.beta_z

    @property
    def damping(self) -> float:
        """D = alpha_z."""
        return self.alpha_z


DEFAULT_DMP_CONFIG = DMPConfig()  # critically damped, Ijspeert et al. (2013) gains


# -- canonical system and basis -------------------------------------------------------------------
def phase(times, tau: float, alpha_x: float) -> np.ndarray:
    """Closed-form canonical system ``x(t) = exp(-alpha_x t / tau)``; times (K,) -> x (K,)."""
    return np.exp(-alpha_x * np.asarray(times, dtype=float) / tau)


def basis_functions(n_basis: int, alpha_x: float, overlap: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Centers ``c`` (N,) and widths ``h`` (N,) of N Gaussians spaced evenly in time.

    ``c_i = x(i tau / (N - 1))``, so the centers are equidistant in t over [0, tau]. Widths make
    neighbours cross at height ``overlap`` halfway between their centers:
    ``exp(-h_i (d_i / 2)^2) = overlap`` with ``d_i = c_i - c_{i+1}`` (the last reuses ``d_{N-2}``).
    """
    n_basis = _check_n_basis(n_basis)
    c = np.exp(-alpha_x * np.linspace(0.0, 1.0, n_basis))
    d = -np.diff(c)
    d = np.append(d, d[-1])
    h = 4.0 * math.log(1.0 / overlap) / d**2
    return c, h


def forcing_features(x, centers: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Normalised, phase-weighted basis ``Phi[k, i] = psi_i(x_k) x_k / sum_j psi_j(x_k)``, (K, N).

    ``f(x_k) = Phi[k] @ W[q]`` for dimension q. Computed with the largest exponent subtracted,
    so the normalisation never divides 0 by 0 far outside the centers.
    """
    x = np.atleast_1d(np.asarray(x, dtype=float))
    log_psi = -widths[None, :] * (x[:, None] - centers[None, :]) ** 2
    log_psi -= log_psi.max(axis=1, keepdims=True)
    psi = np.exp(log_psi)
    return psi * (x / psi.sum(axis=1))[:, None]


def _check_n_basis(n_basis) -> int:
    if isinstance(n_basis, bool) or not isinstance(n_basis, (int, np.integer)) or n_basis < 2:
        raise InputError(f"n_basis must be an integer >= 2 (basis widths come from center spacing), got {n_basis!r}")
    return int(n_basis)


def _finite_array(name: str, value, shape: tuple) -> np.ndarray:
    arr = np.array(value, dtype=float)
    if arr.shape != shape:
        raise InputError(f"{name} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    arr.setflags(write=False)
    return arr


# -- the primitive --------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DMP:
    """A Q-dimensional discrete DMP (Hoffmann et al. 2009 form, see the module docstring).

    Build one with :meth:`fit` (from a demonstration) or :meth:`point_to_point` (zero forcing);
    the constructor takes the fields directly. Instances are immutable; :meth:`with_params`
    returns a new one.

    Attributes
    ----------
    weights : W (Q, N), shape weights in units of position.
    goal : g (Q,).
    start : y0 (Q,), the default start of :meth:`rollout`.
    tau : temporal scaling > 0, the default duration of :meth:`rollout`.
    amplitude : (Q,) positive; per-dimension unit of :attr:`param_scale` (the demonstration's
        range). ``None`` uses ``|g - y0|``; values are floored at 5 % of the largest one.
    config : gains and basis layout.

    Examples
    --------
    >>> t = np.linspace(0.0, 2.0, 201)
    >>> Y = np.stack([np.sin(t + q) for q in range(8)], axis=1)
    >>> dmp = DMP.fit(t, Y, n_basis=11)
    >>> dmp.params.shape
    (96,)
    >>> times, Y_ref = dmp.reference(dmp.params, dt=0.01)
    """

    weights: np.ndarray
    goal: np.ndarray
    start: np.ndarray
    tau: float
    amplitude: np.ndarray | None = None
    config: DMPConfig = field(default=DEFAULT_DMP_CONFIG)

    def __post_init__(self) -> None:
        W = np.array(self.weights, dtype=float)
        if W.ndim != 2 or W.shape[0] < 1:
            raise InputError(f"DMP.weights has shape {W.shape}, expected (Q, N): one row of N weights per dimension")
        Q, N = W.shape
        _check_n_basis(N)
        if not isinstance(self.config, DMPConfig):
            raise InputError(f"DMP.config must be a DMPConfig, got {type(self.config).__name__}")
        object.__setattr__(self, "weights", _finite_array("DMP.weights", W, (Q, N)))
        object.__setattr__(self, "goal", _finite_array("DMP.goal", self.goal, (Q,)))
        object.__setattr__(self, "start", _finite_array("DMP.start", self.start, (Q,)))
        object.__setattr__(self, "tau", _positive("DMP.tau", self.tau))
        amp = np.abs(self.goal - self.start) if self.amplitude is None else self.amplitude
        amp = _finite_array("DMP.amplitude", amp, (Q,))
        if np.any(amp < 0.0):
            raise InputError("DMP.amplitude must be >= 0 in every dimension (it is a range)")
        largest = float(amp.max())
        floor = _AMPLITUDE_FLOOR * largest if largest > 0.0 else 1.0
        object.__setattr__(self, "amplitude", _finite_array("DMP.amplitude", np.maximum(amp, floor), (Q,)))

    # -- construction -----------------------------------------------------------------------------
    @classmethod
    def point_to_point(cls, start, goal, tau: float, n_basis: int = 11,
                       config: DMPConfig = DEFAULT_DMP_CONFIG) -> DMP:
        """A DMP with zero forcing: a smooth, monotone (critically damped gains) motion start -> goal.

        Parameters
        ----------
        start, goal : (Q,).
        tau : duration scale > 0.
        n_basis : N >= 2.
        """
        goal = np.atleast_1d(np.asarray(goal, dtype=float))
        return cls(np.zeros((goal.shape[0], _check_n_basis(n_basis))), goal, start, tau, None, config)

    @classmethod
    def fit(cls, times, Y, n_basis: int = 11, config: DMPConfig = DEFAULT_DMP_CONFIG) -> DMP:
        """Learn a DMP from one demonstration (Ijspeert et al. 2013, Sec. 2.1.4).

        ``tau`` is the demonstration's duration, ``y0 = Y[0]``, ``g = Y[-1]``. Velocities and
        accelerations come from second-order finite differences (non-uniform times allowed).
        The target forcing term, the transformation system solved for f,

            f_target = (tau^2 ddy + D tau dy) / K - (g - y) + (g - y0) x,

        is matched by ridge-regularised least squares, ``Phi W^T = F`` for all dimensions at
        once (a global fit, more accurate than locally weighted regression for few bases).

        Parameters
        ----------
        times : (K,) strictly increasing sample times, K >= 3; shifted to start at 0.
        Y : (K, Q) demonstrated positions.
        n_basis : N >= 2 basis functions per dimension.
        config : gains and basis layout.

        Returns
        -------
        dmp : the fitted DMP; ``amplitude`` is the range ``max - min`` of Y per dimension.
        """
        n_basis = _check_n_basis(n_basis)
        if not isinstance(config, DMPConfig):
            raise InputError(f"config must be a DMPConfig, got {type(config).__name__}")
        t = np.asarray(times, dtype=float)
        Y = np.asarray(Y, dtype=float)
        if t.ndim != 1 or t.shape[0] < 3:
            raise InputError(f"times has shape {t.shape}, expected (K,) with K >= 3 samples")
        if Y.ndim == 1:
            Y = Y[:, None]
        if Y.ndim != 2 or Y.shape[0] != t.shape[0]:
            raise InputError(f"Y has shape {Y.shape}, expected (K, Q) = ({t.shape[0]}, Q) to match times")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(Y))):
            raise InputError("the demonstration (times or Y) contains NaN or inf; clean or crop it before fitting")
        if np.any(np.diff(t) <= 0.0):
            raise InputError("times must be strictly increasing (repeated or unsorted sample times)")
        t = t - t[0]
        tau = float(t[-1])
        K, D = config.stiffness, config.damping
        dY = np.gradient(Y, t, axis=0, edge_order=2)
        ddY = np.gradient(dY, t, axis=0, edge_order=2)
        y0, g = Y[0], Y[-1]
        x = phase(t, tau, config.alpha_x)
        F = (tau**2 * ddY + D * tau * dY) / K - (g - Y) + np.outer(x, g - y0)  # (K, Q)
        c, h = basis_functions(n_basis, config.alpha_x, config.overlap)
        Phi = forcing_features(x, c, h)  # (K, N)
        lam = config.ridge * float(np.mean(np.sum(Phi**2, axis=0)))
        A = np.vstack([Phi, math.sqrt(lam) * np.eye(n_basis)]) if lam > 0.0 else Phi
        B = np.vstack([F, np.zeros((n_basis, Y.shape[1]))]) if lam > 0.0 else F
        W_T, *_ = np.linalg.lstsq(A, B, rcond=None)  # (N, Q); QR/SVD, no normal-equation inverse
        return cls(W_T.T, g, y0, tau, Y.max(axis=0) - Y.min(axis=0), config)

    # -- sizes and basis ---------------------------------------------------------------------------
    @property
    def n_dims(self) -> int:
        """Q."""
        return self.weights.shape[0]

    @property
    def n_basis(self) -> int:
        """N."""
        return self.weights.shape[1]

    @property
    def n_params(self) -> int:
        """Q (N + 1), the length of :attr:`params` (96 for Q = 8, N = 11)."""
        return self.n_dims * (self.n_basis + 1)

    @property
    def centers(self) -> np.ndarray:
        """Basis centers c (N,) in phase space."""
        return basis_functions(self.n_basis, self.config.alpha_x, self.config.overlap)[0]

    @property
    def widths(self) -> np.ndarray:
        """Basis widths h (N,) in phase space."""
        return basis_functions(self.n_basis, self.config.alpha_x, self.config.overlap)[1]

    # -- parameter vector for black-box learning ---------------------------------------------------
    @property
    def params(self) -> np.ndarray:
        """(Q (N + 1),) dimension-major: ``reshape(Q, N + 1)[q] = (W[q, :], g[q])``."""
        return np.hstack([self.weights, self.goal[:, None]]).ravel()

    @property
    def param_scale(self) -> np.ndarray:
        """(Q (N + 1),) per-parameter unit, laid out like :attr:`params`.

        A change of one scale shifts the attractor by about one amplitude of its dimension: the
        goal's scale is ``amplitude[q]``, weight i's is ``amplitude[q] / c_i`` since basis i acts
        where ``x ~ c_i`` and contributes ``w_i x``. So one relative exploration std (PoWER's or
        CMA-ES's ``sigma * param_scale``) perturbs early and late weights and the goal alike.
        """
        S = np.hstack([self.amplitude[:, None] / self.centers[None, :], self.amplitude[:, None]])
        return S.ravel()

    def with_params(self, params) -> DMP:
        """A copy with weights and goals from ``params`` (Q (N + 1),); start, tau, amplitude kept."""
        p = np.asarray(params, dtype=float)
        Q, N = self.n_dims, self.n_basis
        if p.shape != (self.n_params,):
            raise InputError(
                f"params has shape {p.shape}, expected ({self.n_params},) = Q * (N + 1) = {Q} * ({N} + 1), "
                "dimension-major: params.reshape(Q, N + 1)[q] = (weights of q, goal of q)"
            )
        if not np.all(np.isfinite(p)):
            raise InputError("params contains NaN or inf")
        P = p.reshape(Q, N + 1)
        return replace(self, weights=P[:, :N], goal=P[:, N])

    def with_goal(self, goal) -> DMP:
        """A copy with a new goal (Q,), the shape weights kept."""
        return replace(self, goal=goal)

    def reference(self, params, dt: float, duration: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Reference positions of the DMP with ``params``: ``times`` (K,), ``Y`` (K, Q) (see :meth:`rollout`)."""
        times, Y, _, _ = self.with_params(params).rollout(dt, duration)
        return times, Y

    # -- integration ---------------------------------------------------------------------------------
    def forcing(self, times, tau: float | None = None) -> np.ndarray:
        """Forcing term ``f(x(t))`` (K, Q) at times (K,) for temporal scaling ``tau``."""
        tau = self.tau if tau is None else _positive("tau", tau)
        x = phase(times, tau, self.config.alpha_x)
        c, h = basis_functions(self.n_basis, self.config.alpha_x, self.config.overlap)
        return forcing_features(x, c, h) @ self.weights.T

    def rollout(self, dt: float, duration: float | None = None, *, start=None, start_velocity=None,
                goal=None, tau: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Integrate the DMP (RK4, closed-form phase) from rest at ``start``.

        Parameters
        ----------
        dt : output time step > 0.
        duration : length of the rollout (default ``tau``); may exceed tau, then the motion
            settles at the goal. The K = round(duration / dt) + 1 output times are ``k dt``.
        start : y0 (Q,), default :attr:`start`; the Hoffmann term ``-K (g - y0) x`` uses it.
        start_velocity : dy at t = 0 (Q,), default zeros.
        goal : g (Q,), default :attr:`goal`.
        tau : temporal scaling, default :attr:`tau` (larger is slower).

        Returns
        -------
        times : (K,), Y : (K, Q) positions, dY : (K, Q) velocities, ddY : (K, Q) accelerations
            (from the dynamics, not finite differences).
        """
        dt = _positive("dt", dt)
        tau = self.tau if tau is None else _positive("tau", tau)
        duration = tau if duration is None else _positive("duration", duration)
        Q = self.n_dims
        y0 = self.start if start is None else _finite_array("start", start, (Q,))
        v0 = np.zeros(Q) if start_velocity is None else _finite_array("start_velocity", start_velocity, (Q,))
        g = self.goal if goal is None else _finite_array("goal", goal, (Q,))
        n_out = int(round(duration / dt)) + 1
        if n_out > 10_000_000:
            raise InputError(f"duration / dt = {duration / dt:g} steps is too many; use a larger dt")
        K, D = self.config.stiffness, self.config.damping
        n_sub = max(1, math.ceil(dt * math.sqrt(K) / tau / _MAX_STEP_RATE))
        h = dt / n_sub
        n_steps = (n_out - 1) * n_sub
        # Input u(t) = K (g - (g - y0) x + f(x)) / tau^2 at every RK4 stage time t_j, t_j + h/2, t_j + h.
        stage_times = h * np.arange(2 * n_steps + 1) / 2.0
        x = phase(stage_times, tau, self.config.alpha_x)
        u = (K / tau**2) * (g[None, :] - np.outer(x, g - y0) + self.forcing(stage_times, tau))  # (2 n_steps + 1, Q)
        a_k, a_d = K / tau**2, D / tau

        def accel(y, v, u_t):
            return u_t - a_k * y - a_d * v  # tau^2 ddy = K (g - y) - D tau dy - K (g - y0) x + K f

        Y = np.empty((n_out, Q))
        V = np.empty((n_out, Q))
        A = np.empty((n_out, Q))
        y, v = y0.copy(), v0.copy()
        Y[0], V[0], A[0] = y, v, accel(y, v, u[0])
        for j in range(n_steps):  # classical RK4 on (y, v)
            u0, um, u1 = u[2 * j], u[2 * j + 1], u[2 * j + 2]
            k1y, k1v = v, accel(y, v, u0)
            k2y, k2v = v + 0.5 * h * k1v, accel(y + 0.5 * h * k1y, v + 0.5 * h * k1v, um)
            k3y, k3v = v + 0.5 * h * k2v, accel(y + 0.5 * h * k2y, v + 0.5 * h * k2v, um)
            k4y, k4v = v + h * k3v, accel(y + h * k3y, v + h * k3v, u1)
            y = y + (h / 6.0) * (k1y + 2.0 * k2y + 2.0 * k3y + k4y)
            v = v + (h / 6.0) * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
            if (j + 1) % n_sub == 0:
                k = (j + 1) // n_sub
                Y[k], V[k], A[k] = y, v, accel(y, v, u1)
        return dt * np.arange(n_out), Y, V, A
