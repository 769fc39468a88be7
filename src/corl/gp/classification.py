"""Binary GP classification with a constant prior mean: the success model g_S (Eq. 13, Sec. VII-C).

The latent function g ~ GP(m0, k) gives ``p(s = +1 | theta) = sigma(g(theta))`` with the logistic
sigma (Eq. 13). The posterior over g is approximated with Laplace's method, GPML Alg. 3.1 (mode),
3.2 (prediction) and 5.1 (marginal likelihood gradient), adapted to a constant prior mean
``m0 != 0`` by writing ``f = m0 + K a``. A negative ``m0`` (paper: -7) makes the model predict
failure away from the data.

Glossary
--------
X      : training inputs (d, m); one row per theta
y      : labels in {-1, +1}, (d,); the outcomes s
t      : labels in {0, 1}, ``(y + 1) / 2``
m0     : constant prior mean of the latent function
K      : Gram matrix ``k(X, X)``, (d, d)
a      : Newton weights with ``f = m0 + K a``, (d,)
f      : latent values at the training inputs, (d,); ``f_hat`` at the posterior mode
pi     : ``sigma(f)``, (d,)
dlp    : ``d log p(y | f) / df = t - pi``, (d,)
W      : ``-d^2 log p(y | f) / df^2 = pi (1 - pi)``, (d,) (the diagonal of GPML's W)
sW     : ``sqrt(W)``, (d,)
B      : ``I + sW K sW``, (d, d); ``L`` is its lower Cholesky factor
Psi    : ``-1/2 a^T K a + log p(y | f)``, the log posterior up to a constant (GPML eq. 3.12)
Xs     : test inputs (s, m); ``ks = k(X, Xs)`` (d, s)
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import linalg
from scipy.linalg import lapack
from scipy.special import expit, ndtr

from corl.errors import InputError, StateError
from corl.gp.kernels import SquaredExponential
from corl.gp.regression import check_training_data, gaussian_posterior, maximize_in_log_space, mean_on_lattice, to_log_bounds
from corl.numerics import as_matrix, cho_solve, cholesky, floor_variance

__all__ = [
    "GPClassifier",
    "LaplaceConvergenceWarning",
    "expected_sigmoid",
    "labels_to_pm1",
]


class LaplaceConvergenceWarning(UserWarning):
    """The Newton iteration for the Laplace mode stopped at ``max_iter`` before converging."""


# ---------------------------------------------------------------------------------------------
# Likelihood and labels
# ---------------------------------------------------------------------------------------------
def labels_to_pm1(s) -> np.ndarray:
    """Labels as a float vector in {-1, +1}; accepts bool, {0, 1} or {-1, +1}. Returns (d,)."""
    arr = np.asarray(s)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise InputError(f"labels must be a vector (d,), got shape {arr.shape}")
    if arr.dtype == bool:
        return np.where(arr, 1.0, -1.0)
    try:
        vals = arr.astype(float)
    except (TypeError, ValueError):
        raise InputError(f"labels must be bool, {{0, 1}} or {{-1, +1}}, got dtype {arr.dtype}") from None
    present = set(np.unique(vals).tolist())
    if present <= {0.0, 1.0}:
        return np.where(vals == 1.0, 1.0, -1.0)
    if present <= {-1.0, 1.0}:
        return vals
    bad = sorted(present - {-1.0, 0.0, 1.0}, key=str)[:5]
    raise InputError(
        f"labels must be bool, {{0, 1}} or {{-1, +1}} (not a mix of 0 and -1); got values such as {bad or sorted(present)}"
    )


def _log_likelihood(y: np.ndarray, f: np.ndarray) -> float:
    """``log p(y | f) = sum log sigma(y f) = -sum log(1 + exp(-y f))``, stable for any f."""
    return -float(np.sum(np.logaddexp(0.0, -y * f)))


# ---------------------------------------------------------------------------------------------
# Laplace mode (GPML Alg. 3.1 with a constant mean and a damped Newton step)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class LaplaceMode:
    """Posterior mode and the quantities GPML Alg. 3.2 needs; vectors are (d,), ``L`` is (d, d)."""

    a: np.ndarray
    f: np.ndarray
    dlp: np.ndarray
    W: np.ndarray
    sW: np.ndarray
    L: np.ndarray
    psi: float
    n_iter: int
    converged: bool

    @property
    def log_marginal_likelihood(self) -> float:
        """GPML eq. 3.32: ``Psi(f_hat) - sum log L_ii`` (``log|B| / 2 = sum log L_ii``)."""
        return self.psi - float(np.sum(np.log(np.diag(self.L))))


def _newton_system(K: np.ndarray, f: np.ndarray, t: np.ndarray):
    """pi, dlp, W, sW and the Cholesky factor of B at latent values f."""
    pi = expit(f)
    W = pi * expit(-f)  # pi (1 - pi) without cancellation for large f
    sW = np.sqrt(W)
    B = sW[:, None] * K * sW[None, :]
    B.flat[:: f.size + 1] += 1.0
    # B has all eigenvalues >= 1, so plain LAPACK potrf (no wrapper overhead, which dominates
    # for d ~ 50 inside the Newton loop) nearly always succeeds; the jitter ladder is the fallback.
    L, info = lapack.dpotrf(B, lower=1, clean=1)
    if info != 0:
        L, _ = cholesky(B, what="Laplace matrix B = I + W^1/2 K W^1/2")
    return pi, t - pi, W, sW, L


def _cho_solve(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(L L^T)^{-1} b`` via LAPACK potrs, for the small systems of the Newton loop."""
    x, info = lapack.dpotrs(L, b, lower=1)
    if info != 0:  # only for malformed input; numerics.cho_solve reports it
        return cho_solve(L, b)
    return x


def find_mode(K, y, m0: float, a0=None, *, max_iter: int = 100, tol: float = 1e-10) -> LaplaceMode:
    """Mode of the Laplace approximation by damped Newton on ``a`` (GPML Alg. 3.1).

    Parameters
    ----------
    K : (d, d) Gram matrix; may be singular (``a`` is used so that K is never inverted).
    y : (d,) labels in {-1, +1}.
    m0 : constant prior mean.
    a0 : (d,) starting weights, e.g. a previous mode padded with zeros; 0 (f = m0) when None.
        The start with the larger Psi of ``a0`` and 0 is used.
    max_iter : maximum number of Newton steps.
    tol : stop when a step raises Psi by less than ``tol``.

    Returns
    -------
    LaplaceMode
    """
    d = y.size
    t = 0.5 * (y + 1.0)

    def psi_of(a, f):  # GPML eq. 3.12 with f - m0 = K a
        return -0.5 * float(a @ (f - m0)) + _log_likelihood(y, f)

    a = np.zeros(d)
    f = np.full(d, float(m0))
    psi = psi_of(a, f)
    if a0 is not None and np.any(a0):
        f0 = m0 + K @ a0
        psi0 = psi_of(a0, f0)
        if psi0 > psi:
            a, f, psi = np.asarray(a0, dtype=float), f0, psi0

    converged, it = d == 0, 0
    while not converged and it < max_iter:
        it += 1
        _, dlp, W, sW, L = _newton_system(K, f, t)
        # Alg. 3.1, lines 6-8 with f - m0 in place of f: the full Newton step gives a_new.
        b = W * (f - m0) + dlp
        a_new = b - sW * _cho_solve(L, sW * (K @ b))
        da = a_new - a
        Kda = K @ da
        slope = float(Kda @ (dlp - a))  # d Psi(a + s da) / ds at s = 0; grad_a Psi = K (dlp - a)
        if slope <= 0.0:  # no ascent left in floating point: at the mode
            converged = True
            break
        # Damping (GPML's infLaplace line search): backtrack until Psi rises enough (Armijo).
        step = 1.0
        while True:
            a_try, f_try = a + step * da, f + step * Kda
            psi_try = psi_of(a_try, f_try)
            if psi_try >= psi + 1e-4 * step * slope or step < 1e-12:
                break
            step *= 0.5
        gain = psi_try - psi
        if gain > 0.0:
            a, f, psi = a_try, f_try, psi_try
        converged = gain < tol
    _, dlp, W, sW, L = _newton_system(K, f, t)
    return LaplaceMode(a, f, dlp, W, sW, L, psi, it, converged)


# ---------------------------------------------------------------------------------------------
# E[sigma(f)] for f ~ N(mu, var)
# ---------------------------------------------------------------------------------------------
_GH_X, _GH_W = np.polynomial.hermite.hermgauss(32)
_GH_X, _GH_W = np.sqrt(2.0) * _GH_X, _GH_W / np.sqrt(np.pi)  # nodes and weights for N(0, 1)
_NARROW_STD = 1.5
# sigma(f) ~= sum_i c_i Phi(lambda_i f) with max |error| = 5.2e-8 over the real line; c_i > 0 and
# sum c_i = 1 (exact limits at +-inf). Fitted offline by minimax over lambda with least-squares c.
_MIX_LAMBDA = np.array([
    0.26465328081121237, 0.3572816987881459, 0.47840275016171396, 0.6392086635552826,
    0.8509853492943281, 1.1391386376780028, 1.8410904122589997,
])
_MIX_C = np.array([
    7.1393395770082751e-03, 9.1373694583299150e-02, 2.8477938397101282e-01, 3.7232553792735651e-01,
    2.1025862014703056e-01, 3.3993846188428767e-02, 1.2957760586392356e-04,
])


def expected_sigmoid(mean, var) -> np.ndarray:
    """``E[sigma(f)]`` for ``f ~ N(mean, var)``, elementwise (GPML eq. 3.25); absolute error < 1e-7.

    For std <= 1.5, 32-node Gauss-Hermite quadrature over the Gaussian (error < 1e-9, also
    relatively accurate in the tails). For wider Gaussians sigma is a steep step on the
    Gaussian's scale and Gauss-Hermite fails (30 nodes err by 1e-2 at std 10), so sigma is replaced
    by a 7-term mixture of probit functions with max error 5.2e-8, and each term is integrated
    exactly: ``E[Phi(lambda f)] = Phi(lambda mean / sqrt(1 + lambda^2 var))``.

    Parameters
    ----------
    mean, var : (s,) arrays (var >= 0), or anything broadcastable.

    Returns
    -------
    p : (s,) in [0, 1].
    """
    mean = np.asarray(mean, dtype=float)
    var = floor_variance(np.asarray(var, dtype=float))
    mean, var = np.broadcast_arrays(mean, var)
    out = np.empty(mean.shape)
    narrow = var <= _NARROW_STD**2
    if np.any(narrow):
        mu, sd = mean[narrow], np.sqrt(var[narrow])
        out[narrow] = expit(mu[:, None] + sd[:, None] * _GH_X) @ _GH_W
    wide = ~narrow
    if np.any(wide):
        mu, v = mean[wide], var[wide]
        z = mu[:, None] * _MIX_LAMBDA / np.sqrt(1.0 + v[:, None] * _MIX_LAMBDA**2)
        out[wide] = ndtr(z) @ _MIX_C
    return np.clip(out, 0.0, 1.0)


# ---------------------------------------------------------------------------------------------
# The classifier
# ---------------------------------------------------------------------------------------------
class GPClassifier:
    """Binary GP classifier with logistic likelihood and Laplace approximation (Eq. 13).

    ``__init__`` only stores settings; :meth:`fit` learns. Hyperparameters stay fixed (the paper
    fixes them): :meth:`fit` always uses ``kernel``; :meth:`optimize_hyperparameters` stores its
    result in ``kernel_`` only. The prior mean is never fitted.

    Parameters
    ----------
    kernel : SquaredExponential, optional
        Covariance of the latent function; defaults to the paper's ``l = 0.4, sf = 10``.
    prior_mean : float
        Constant prior mean ``m0`` of the latent function (paper: -7, so unexplored regions are
        predicted to fail).
    max_iter : maximum Newton steps of the mode search.
    tol : the mode search stops when a Newton step raises Psi by less than ``tol``.
    warm_start : start the mode search from the previous mode when the new inputs extend the
        previous ones (the acquisition loop adds one point per iteration).

    Attributes
    ----------
    kernel_ : kernel used by the fit (differs from ``kernel`` only after optimization).
    X_ : (d, m) inputs; ``y_`` : (d,) labels in {-1, +1}.
    f_hat_ : (d,) posterior mode of the latent function at ``X_``.
    a_ : (d,) Newton weights, ``f_hat_ = m0 + K a_``.
    alpha_ : (d,) ``grad log p(y | f_hat_)``, the weights of the predictive mean (Alg. 3.2, line 4).
    W_ : (d,) negative Hessian of the log likelihood at the mode; ``sW_`` its square root.
    L_ : (d, d) lower Cholesky factor of ``B = I + sW K sW``.
    n_iter_ : Newton steps taken; ``converged_`` : whether the tolerance was met.
    """

    def __init__(
        self,
        kernel: SquaredExponential | None = None,
        prior_mean: float = -7.0,
        *,
        max_iter: int = 100,
        tol: float = 1e-10,
        warm_start: bool = True,
    ):
        self.kernel = SquaredExponential() if kernel is None else kernel
        if not isinstance(self.kernel, SquaredExponential):
            raise InputError(f"kernel must be a SquaredExponential, got {type(kernel).__name__}")
        self.prior_mean = float(prior_mean)
        if not np.isfinite(self.prior_mean):
            raise InputError(f"prior_mean must be finite, got {prior_mean}")
        if int(max_iter) < 1:
            raise InputError(f"max_iter must be >= 1, got {max_iter}")
        if not tol > 0:
            raise InputError(f"tol must be positive, got {tol}")
        self.max_iter, self.tol, self.warm_start = int(max_iter), float(tol), bool(warm_start)

    def __repr__(self) -> str:
        return f"GPClassifier(kernel={self.kernel!r}, prior_mean={self.prior_mean:.4g})"

    # -- fitting -------------------------------------------------------------------------------
    def fit(self, X, s) -> "GPClassifier":
        """Find the Laplace approximation of the posterior for outcomes ``s`` at inputs ``X``.

        Parameters
        ----------
        X : (d, m) inputs (a 1-D array is read as (d, 1)); d = 0 is allowed.
        s : (d,) outcomes: bool, {0, 1} or {-1, +1} (True / 1 = success).

        Returns
        -------
        self
        """
        X, y = self._check_data(X, s)
        a0 = self._warm_start_weights(X)
        return self._fit(X, y, self.kernel, a0)

    def _check_data(self, X, s):
        y = labels_to_pm1(s)
        return check_training_data(X, y, self.kernel, target="s")

    def _warm_start_weights(self, X) -> np.ndarray | None:
        """Previous ``a_`` padded with zeros when ``X`` starts with the previous inputs."""
        if not (self.warm_start and hasattr(self, "a_")):
            return None
        old = self.X_
        if old.shape[1] != X.shape[1] or old.shape[0] > X.shape[0] or not np.array_equal(old, X[: old.shape[0]]):
            return None
        return np.concatenate([self.a_, np.zeros(X.shape[0] - old.shape[0])])

    def _fit(self, X, y, kernel: SquaredExponential, a0) -> "GPClassifier":
        mode = find_mode(kernel(X), y, self.prior_mean, a0, max_iter=self.max_iter, tol=self.tol)
        if not mode.converged:
            warnings.warn(
                f"Laplace mode search stopped after {mode.n_iter} Newton steps without meeting "
                f"tol={self.tol:g}; raise max_iter or check the hyperparameters",
                LaplaceConvergenceWarning,
                stacklevel=3,
            )
        self.X_, self.y_, self.kernel_, self._mode = X, y, kernel, mode
        self.a_, self.f_hat_, self.alpha_ = mode.a, mode.f, mode.dlp
        self.W_, self.sW_, self.L_ = mode.W, mode.sW, mode.L
        self.n_iter_, self.converged_ = mode.n_iter, mode.converged
        self.lml_ = mode.log_marginal_likelihood
        # L^{-1} diag(sW) once per fit: a (d, d) @ (d, s) product is several times faster than a
        # triangular solve with s right-hand sides for every prediction grid.
        d = X.shape[0]
        L_inv = linalg.solve_triangular(mode.L, np.eye(d), lower=True, check_finite=False)
        self._L_inv_sW = L_inv * mode.sW[None, :]
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "L_"):
            raise StateError("this GPClassifier is not fitted yet; call fit(X, s) first")

    # -- prediction (GPML Alg. 3.2) ------------------------------------------------------------
    def predict_latent(self, Xs) -> tuple[np.ndarray, np.ndarray]:
        """Mean and variance of the latent g_S at test inputs.

        Parameters
        ----------
        Xs : (s, m) test inputs.

        Returns
        -------
        mean : (s,), ``m0 + ks^T grad log p(y | f_hat)`` (Alg. 3.2, line 4).
        var : (s,), ``k(x*, x*) - v^T v`` with ``v = L \\ (sW ks)`` (lines 5-6), floored.
        """
        self._check_fitted()
        Xs = as_matrix(Xs, self.X_.shape[1], name="Xs")
        if self.X_.shape[0] == 0:
            return np.full(Xs.shape[0], self.prior_mean), floor_variance(self.kernel_.diag(Xs))
        # Alg. 3.2, lines 4-6: mean = m0 + ks^T dlp, var = kss - |L \ (sW ks)|^2
        return gaussian_posterior(self.kernel_, self.X_, Xs, self.alpha_, self._L_inv_sW, self.prior_mean)

    def latent_mean_on_lattice(self, axes) -> np.ndarray:
        """g_S's latent mean on the lattice spanned by ``axes`` (m 1-D arrays, 'ij' order, flattened):
        :meth:`predict_latent`'s mean up to rounding, from the factorised kernel (:func:`mean_on_lattice`)."""
        self._check_fitted()
        return mean_on_lattice(self.kernel_, self.X_, axes, self.alpha_, self.prior_mean)

    def predict_latent_positive(self, Xs) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`predict_latent` with the variance only where the mean is > 0 (NaN elsewhere).

        ``E[sigma(g)] <= 1/2`` wherever the mean is <= 0, so a caller that only wants points with
        ``p > 1/2`` skips most of the cost on a grid that is mostly unexplored.
        """
        self._check_fitted()
        Xs = as_matrix(Xs, self.X_.shape[1], name="Xs")
        if self.X_.shape[0] == 0:
            mean = np.full(Xs.shape[0], self.prior_mean)
            return mean, np.where(mean > 0, floor_variance(self.kernel_.diag(Xs)), np.nan)
        return gaussian_posterior(self.kernel_, self.X_, Xs, self.alpha_, self._L_inv_sW, self.prior_mean, above=0.0)

    def predict_proba(self, Xs) -> np.ndarray:
        """Averaged predictive probability of success ``E[sigma(g)]`` (GPML eq. 3.25); (s,)."""
        mean, var = self.predict_latent(Xs)
        return expected_sigmoid(mean, var)

    # -- marginal likelihood -------------------------------------------------------------------
    def log_marginal_likelihood(self, log_params=None, eval_gradient: bool = False):
        """Laplace approximation of ``log p(y | X)`` (GPML eq. 3.32).

        Parameters
        ----------
        log_params : (p + 1,), optional
            Kernel log hyperparameters; defaults to the fitted kernel (then no new mode search).
        eval_gradient : also return the gradient with respect to ``log_params`` (GPML Alg. 5.1,
            including the implicit dependence of the mode on the hyperparameters).

        Returns
        -------
        lml : float
        grad : (p + 1,), only when ``eval_gradient``.
        """
        self._check_fitted()
        kernel = self.kernel_ if log_params is None else self.kernel_.with_log_params(log_params)
        X, y = self.X_, self.y_
        if X.shape[0] == 0:
            return (0.0, np.zeros(kernel.n_params)) if eval_gradient else 0.0
        K, dK = kernel.gradient(X)
        if log_params is None:
            mode = self._mode
        else:
            mode = find_mode(K, y, self.prior_mean, self.a_, max_iter=self.max_iter, tol=self.tol)
        lml = mode.log_marginal_likelihood
        if not eval_gradient:
            return lml
        return lml, _lml_gradient(K, dK, mode)

    def optimize_hyperparameters(self, X, s, bounds=None, n_restarts: int = 0, seed=0) -> "GPClassifier":
        """Fit with kernel hyperparameters that maximize the Laplace marginal likelihood.

        The prior mean stays fixed: it encodes the designer's choice that unexplored regions fail.

        Parameters
        ----------
        X : (d, m) inputs, d >= 1; s : (d,) outcomes.
        bounds : (p + 1, 2), optional
            ``(low, high)`` in natural units for each length scale and the signal std. Defaults to
            length scales in [1e-2, 1e2] and signal std in [1e-2, 1e2].
        n_restarts : extra starts drawn uniformly in log space.
        seed : seed of the restart generator.

        Returns
        -------
        self, fitted with the optimized ``kernel_``.
        """
        X, y = self._check_data(X, s)
        if X.shape[0] == 0:
            raise InputError("optimize_hyperparameters needs at least one data point")
        p = self.kernel.n_params
        default = np.array([[1e-2, 1e2]] * p)
        log_bounds = to_log_bounds(bounds, p, default)
        self._fit(X, y, self.kernel, self._warm_start_weights(X))
        best = maximize_in_log_space(
            lambda v: self.log_marginal_likelihood(v, eval_gradient=True),
            self.kernel.log_params, log_bounds, n_restarts, seed, jac=True,
        )
        return self._fit(X, y, self.kernel.with_log_params(best), self.a_)


def _lml_gradient(K: np.ndarray, dK: np.ndarray, mode: LaplaceMode) -> np.ndarray:
    """GPML Alg. 5.1, lines 7-15: gradient of eq. 3.32 wrt kernel log hyperparameters, (p,).

    The prior mean is constant in the hyperparameters, so ``f_hat - m0 = K a`` changes exactly as
    ``f_hat`` does in the zero-mean derivation.
    """
    sW, L, a, dlp, W = mode.sW, mode.L, mode.a, mode.dlp, mode.W
    R = sW[:, None] * cho_solve(L, np.diag(sW))  # line 7: R = sW L^T \ (L \ sW)
    C = linalg.solve_triangular(L, sW[:, None] * K, lower=True, check_finite=False)  # line 8
    # line 9: s2 = d(-1/2 log|B|) / d f_hat = -1/2 diag((K^-1 + W)^-1) dW/df, and
    # diag((K^-1 + W)^-1) = diag(K) - diag(C^T C). For the logistic dW/df = W (1 - 2 pi) =
    # -d^3 log p / df^3. (This is the sign of GPML's infLaplace.m; it is checked against finite
    # differences in the tests.)
    dW = W * (1.0 - 2.0 * expit(mode.f))
    s2 = -0.5 * (np.diag(K) - np.einsum("ij,ij->j", C, C)) * dW
    grad = np.empty(dK.shape[0])
    for j, Cj in enumerate(dK):  # p <= m + 1 hyperparameters, never a loop over points
        s1 = 0.5 * a @ Cj @ a - 0.5 * np.sum(R * Cj)  # line 11, explicit part
        b = Cj @ dlp  # line 12
        s3 = b - K @ (R @ b)  # line 13
        grad[j] = s1 + s2 @ s3  # line 14
    return grad
