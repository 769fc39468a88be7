"""Gaussian process regression with a constant prior mean: the return model g_R (Eq. 11-12).

Glossary
--------
X        : training inputs (d, m); one row per theta (the paper's Omega)
y        : training targets (d,); the returns r
Xs       : test inputs (s, m); one row per theta_*
m0       : constant prior mean ``m(theta) = m0`` (0 for g_R in the paper)
K        : Gram matrix ``k(X, X)``, (d, d)
Ky       : ``K + sigma^2 I`` (plus jitter if the Cholesky needed it), (d, d)
L        : lower Cholesky factor of Ky, (d, d)
alpha    : ``Ky^{-1} (y - m0)``, (d,)  (GPML Alg. 2.1, line 3)
ks       : ``k(X, Xs)``, (d, s)
sigma    : observation noise standard deviation ``noise_std``
log_params : kernel log hyperparameters followed by ``log sigma``, shape (p + 2,)
"""

from __future__ import annotations


import numpy as np
from scipy import linalg

from corl.errors import InputError, NumericalError, StateError
from corl.gp.kernels import SquaredExponential
from corl.numerics import as_matrix, as_vector, cho_solve, cholesky, floor_variance

__all__ = ["GPRegression"]

_LOG_2PI = float(np.log(2.0 * np.pi))


def _check_positive(value, name: str) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{name} must be positive and finite, got {value}")
    return v


def check_training_data(X, y, kernel: SquaredExponential, *, target: str = "y"):
    """Validate training data; returns X (d, m) and y (d,) as float arrays.

    A 1-D ``X`` is read as d points in one dimension.
    """
    y = as_vector(y, name=target)
    X = np.asarray(X, dtype=float)
    if X.ndim == 1:
        X = X.reshape(-1, 1)
    m = kernel.lengthscales.size if kernel.ard else None
    X = as_matrix(X, m, name="X")
    if X.shape[0] != y.shape[0]:
        raise InputError(f"X has {X.shape[0]} rows but {target} has {y.shape[0]} entries; one per point")
    return X, y


def to_log_bounds(bounds, n_params: int, default: np.ndarray) -> np.ndarray:
    """Bounds given in natural units, (n_params, 2), converted to log space."""
    b = default if bounds is None else np.asarray(bounds, dtype=float)
    if b.shape != (n_params, 2):
        raise InputError(f"bounds has shape {b.shape}, expected ({n_params}, 2) as (low, high) per parameter")
    if not np.all(np.isfinite(b)) or np.any(b[:, 0] <= 0) or np.any(b[:, 0] >= b[:, 1]):
        raise InputError(f"bounds need 0 < low < high and finite values, got {b.tolist()}")
    return np.log(b)


def maximize_in_log_space(objective, x0: np.ndarray, log_bounds: np.ndarray, n_restarts: int, seed, *, jac: bool):
    """Maximize ``objective(log_params)`` with L-BFGS-B from ``x0`` and ``n_restarts`` random starts.

    ``objective`` returns the value (``jac=False``) or ``(value, gradient)``; a start whose
    objective fails numerically is skipped. Returns the best log_params found, (p,).
    """
    from scipy import optimize  # only hyperparameter fitting needs it; keeps `import corl.gp` light

    rng = np.random.default_rng(seed)
    lo, hi = log_bounds[:, 0], log_bounds[:, 1]
    starts = [np.clip(x0, lo, hi)] + [rng.uniform(lo, hi) for _ in range(int(n_restarts))]

    def negative(v):
        try:
            out = objective(v)
        except NumericalError:
            return (np.inf, np.zeros_like(v)) if jac else np.inf
        if jac:
            return -out[0], -out[1]
        return -out

    best_x, best_f = None, np.inf
    for start in starts:
        res = optimize.minimize(negative, start, jac=jac, method="L-BFGS-B", bounds=list(zip(lo, hi)))
        if np.isfinite(res.fun) and res.fun < best_f:
            best_x, best_f = res.x, float(res.fun)
    if best_x is None:
        raise NumericalError("hyperparameter optimization failed from every start; narrow the bounds")
    return best_x


_CHUNK_ELEMENTS = 1 << 15  # test points per block * training points: 256 kB blocks stay in cache


def mean_on_lattice(kernel: SquaredExponential, X, axes, weights, prior_mean: float) -> np.ndarray:
    """``m0 + ks^T weights`` on the lattice ``axes[0] x axes[1] x ...`` ('ij' order, flattened).

    The squared exponential factorises over coordinates, ``k(x, x_i) = sf^2 prod_j
    exp(-(x_j - x_ij)^2 / (2 l_j^2))``: m tables of (n_j, d) exponentials and products instead of
    ``prod n_j * d`` exponentials. X : (d, m); axes : m 1-D arrays; weights : (d,). Returns (prod n_j,).
    """
    axes = [np.asarray(a, dtype=float).reshape(-1) for a in axes]
    if len(axes) != X.shape[1]:
        raise InputError(f"need {X.shape[1]} axes, got {len(axes)}")
    if X.shape[0] == 0:
        return np.full(int(np.prod([a.size for a in axes])), float(prior_mean))
    ls = np.broadcast_to(np.asarray(kernel.lengthscales, dtype=float), (len(axes),))
    tables = [np.exp(-0.5 * ((a[:, None] - X[None, :, j]) / ls[j]) ** 2) for j, a in enumerate(axes)]
    out = tables[0] * (weights * float(kernel.signal_std) ** 2)  # (n_0, d)
    for table in tables[1:-1]:  # (N, d) x (n_j, d) -> (N * n_j, d), 'ij' order
        out = (out[:, None, :] * table[None, :, :]).reshape(-1, table.shape[1])
    out = out.sum(axis=1) if len(tables) == 1 else out @ tables[-1].T
    return out.reshape(-1) + prior_mean


def gaussian_posterior(kernel: SquaredExponential, X, Xs, weights, V, prior_mean: float, above=None):
    """Mean and variance ``m0 + ks^T weights`` and ``k(x*, x*) - |V ks|^2`` at test inputs.

    The common last step of GPML Alg. 2.1 (``V = L^{-1}``) and Alg. 3.2 (``V = L^{-1} sW``).
    Test points are processed in blocks so the (d, block) temporaries stay in cache.

    Parameters
    ----------
    kernel : covariance function.
    X : (d, m) training inputs, d >= 1; Xs : (s, m) test inputs.
    weights : (d,); V : (d, d).
    above : optional float: the variance only where the mean exceeds it (most of the cost); NaN
        elsewhere.

    Returns
    -------
    mean, var : (s,) each; var is floored.
    """
    s = Xs.shape[0]
    mean, var = np.empty(s), kernel.diag(Xs)
    block = max(64, _CHUNK_ELEMENTS // X.shape[0])
    for start in range(0, s, block):
        rows = slice(start, start + block)
        ks = kernel(Xs[rows], X).T  # (d, block)
        mean[rows] = weights @ ks
        if above is not None:
            keep = mean[rows] + prior_mean > above
            var[rows][~keep] = np.nan
            ks = ks[:, keep]
            rows = np.arange(start, min(start + block, s))[keep]
        v = V @ ks
        var[rows] -= np.einsum("ij,ij->j", v, v)
    return mean + prior_mean, floor_variance(var)


class GPRegression:
    """GP regression with a constant prior mean and Gaussian noise (Eq. 11-12, GPML Alg. 2.1).

    ``__init__`` only stores settings; :meth:`fit` learns. Hyperparameters stay fixed (the paper
    fixes them, Sec. VIII): :meth:`fit` always uses ``kernel`` and ``noise_std``.
    :meth:`optimize_hyperparameters` fits with optimized values stored in ``kernel_`` and
    ``noise_std_``; to keep them for later fits, build
    ``GPRegression(gp.kernel_, gp.noise_std_, gp.prior_mean)``.

    Parameters
    ----------
    kernel : SquaredExponential, optional
        Covariance function; defaults to the paper's ``l = 0.4, sf = 10``.
    noise_std : float
        Observation noise standard deviation ``sigma`` (paper: 0.11).
    prior_mean : float
        Constant prior mean ``m0`` (paper: 0).

    Attributes
    ----------
    kernel_ : SquaredExponential, the kernel used by the fit (differs from ``kernel`` only after
        hyperparameter optimization); ``noise_std_`` likewise.
    X_ : (d, m) training inputs; ``y_`` : (d,) targets.
    L_ : (d, d) lower Cholesky factor of ``K + sigma^2 I + jitter_ I``.
    alpha_ : (d,) ``(K + sigma^2 I)^{-1} (y - m0)``.
    jitter_ : float, jitter the Cholesky needed (0 for well-separated inputs).
    """

    def __init__(self, kernel: SquaredExponential | None = None, noise_std: float = 0.11, prior_mean: float = 0.0):
        self.kernel = SquaredExponential() if kernel is None else kernel
        if not isinstance(self.kernel, SquaredExponential):
            raise InputError(f"kernel must be a SquaredExponential, got {type(kernel).__name__}")
        self.noise_std = _check_positive(noise_std, "noise_std")
        self.prior_mean = float(prior_mean)
        if not np.isfinite(self.prior_mean):
            raise InputError(f"prior_mean must be finite, got {prior_mean}")

    def __repr__(self) -> str:
        return f"GPRegression(kernel={self.kernel!r}, noise_std={self.noise_std:.4g}, prior_mean={self.prior_mean:.4g})"

    # -- fitting -------------------------------------------------------------------------------
    def fit(self, X, y) -> "GPRegression":
        """Condition the GP on data with the current hyperparameters.

        Parameters
        ----------
        X : (d, m) inputs (a 1-D array is read as (d, 1)); d = 0 is allowed.
        y : (d,) targets.

        Returns
        -------
        self
        """
        X, y = check_training_data(X, y, self.kernel)
        return self._fit(X, y, self.kernel, self.noise_std)

    def _fit(self, X, y, kernel: SquaredExponential, noise_std: float) -> "GPRegression":
        self.X_, self.y_ = X, y
        self.kernel_, self.noise_std_ = kernel, noise_std
        d = X.shape[0]
        # GPML Alg. 2.1, lines 2-3: L = chol(K + sigma^2 I), alpha = L^T \ (L \ (y - m0)).
        Ky = kernel(X) + noise_std**2 * np.eye(d)
        self.L_, self.jitter_ = cholesky(Ky, what="GP regression matrix K + sigma^2 I")
        self.alpha_ = cho_solve(self.L_, y - self.prior_mean) if d else np.zeros(0)
        # L^{-1} once per fit: a (d, d) @ (d, s) product is several times faster than a
        # triangular solve with s right-hand sides for every prediction grid.
        self._L_inv = linalg.solve_triangular(self.L_, np.eye(d), lower=True, check_finite=False)
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "L_"):
            raise StateError("this GPRegression is not fitted yet; call fit(X, y) first")

    # -- prediction ----------------------------------------------------------------------------
    def predict(self, Xs, include_noise: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Posterior mean and variance at test inputs (Eq. 11-12).

        Parameters
        ----------
        Xs : (s, m) test inputs (a 1-D array is read as (s, 1) for m = 1).
        include_noise : add ``sigma^2`` to the variance (predict an observation, not R itself).

        Returns
        -------
        mean : (s,)
        var : (s,), floored at ``numerics.VARIANCE_FLOOR``.
        """
        self._check_fitted()
        Xs = as_matrix(Xs, self.X_.shape[1], name="Xs")
        if self.X_.shape[0] == 0:
            mean, var = np.full(Xs.shape[0], self.prior_mean), self.kernel_.diag(Xs)
        else:
            # Eq. 11-12 as GPML Alg. 2.1 lines 4-6: mean = m0 + ks^T alpha, var = kss - |L \ ks|^2
            mean, var = gaussian_posterior(self.kernel_, self.X_, Xs, self.alpha_, self._L_inv, self.prior_mean)
        if include_noise:
            var = var + self.noise_std_**2
        return mean, floor_variance(var)

    # -- marginal likelihood -------------------------------------------------------------------
    @property
    def log_params_(self) -> np.ndarray:
        """Fitted ``[kernel log_params..., log noise_std]``, shape (p + 2,)."""
        self._check_fitted()
        return np.append(self.kernel_.log_params, np.log(self.noise_std_))

    def log_marginal_likelihood(self, log_params=None, eval_gradient: bool = False):
        """``log p(y | X)`` of the training data (GPML eq. 2.30 with mean ``m0``).

        Parameters
        ----------
        log_params : (p + 2,), optional
            ``[kernel log_params..., log noise_std]``; defaults to the fitted values.
        eval_gradient : also return the gradient with respect to ``log_params`` (GPML eq. 5.9).

        Returns
        -------
        lml : float
        grad : (p + 2,), only when ``eval_gradient``.
        """
        self._check_fitted()
        if log_params is None:
            log_params = self.log_params_
        v = np.asarray(log_params, dtype=float).reshape(-1)
        kernel = self.kernel_.with_log_params(v[:-1])
        noise_var = float(np.exp(2.0 * v[-1]))
        X, r = self.X_, self.y_ - self.prior_mean
        d = X.shape[0]
        if d == 0:
            return (0.0, np.zeros(v.size)) if eval_gradient else 0.0
        K, dK = kernel.gradient(X)
        L, _ = cholesky(K + noise_var * np.eye(d), what="GP regression matrix K + sigma^2 I")
        alpha = cho_solve(L, r)
        # GPML Alg. 2.1, line 8: -1/2 r^T alpha - sum log L_ii - d/2 log 2 pi.
        lml = -0.5 * r @ alpha - np.sum(np.log(np.diag(L))) - 0.5 * d * _LOG_2PI
        if not eval_gradient:
            return float(lml)
        # GPML eq. 5.9: d lml / d p_j = 1/2 tr((alpha alpha^T - Ky^{-1}) dKy/dp_j).
        inner = np.outer(alpha, alpha) - cho_solve(L, np.eye(d))
        grad = np.empty(v.size)
        grad[:-1] = 0.5 * np.einsum("ij,kji->k", inner, dK)
        grad[-1] = noise_var * np.trace(inner)  # dKy / d log sigma = 2 sigma^2 I
        return float(lml), grad

    def optimize_hyperparameters(self, X, y, bounds=None, n_restarts: int = 0, seed=0) -> "GPRegression":
        """Fit with hyperparameters that maximize the log marginal likelihood (L-BFGS-B in log space).

        Parameters
        ----------
        X : (d, m) inputs, d >= 1; y : (d,) targets.
        bounds : (p + 2, 2), optional
            ``(low, high)`` in natural units for each length scale, the signal std and the noise
            std, in the order of :attr:`log_params_`. Defaults to length scales in [1e-2, 1e2],
            signal std in [1e-3, 1e3], noise std in [1e-4, 1e2].
        n_restarts : extra starts drawn uniformly in log space (the first start is the current
            hyperparameters).
        seed : seed of the restart generator.

        Returns
        -------
        self, fitted with the optimized ``kernel_`` and ``noise_std_``.
        """
        X, y = check_training_data(X, y, self.kernel)
        if X.shape[0] == 0:
            raise InputError("optimize_hyperparameters needs at least one data point")
        p = self.kernel.n_params - 1
        default = np.array([[1e-2, 1e2]] * p + [[1e-3, 1e3], [1e-4, 1e2]])
        log_bounds = to_log_bounds(bounds, p + 2, default)
        self._fit(X, y, self.kernel, self.noise_std)
        x0 = self.log_params_

        best = maximize_in_log_space(
            lambda v: self.log_marginal_likelihood(v, eval_gradient=True), x0, log_bounds, n_restarts, seed, jac=True
        )
        return self._fit(X, y, self.kernel.with_log_params(best[:-1]), float(np.exp(best[-1])))
