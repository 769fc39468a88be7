"""Covariance functions of the Gaussian processes g_R and g_S (Sec. VII-C).

Glossary
--------
X, Y        : input points, shapes (a, m) and (b, m); one row is one theta
m           : input dimension (the dimension of theta)
K           : covariance (Gram) matrix ``K[i, j] = k(X[i], Y[j])``, shape (a, b)
l           : length scales, shape (m,) (ARD) or a single shared value; ``Lambda = diag(l^2)``
sf          : signal standard deviation ``sigma_sf``; ``k(x, x) = sf^2``
log_params  : hyperparameters in log space, ``[log l_1, ..., log l_p, log sf]``, shape (p + 1,)
              with p = 1 for a shared length scale and p = m for ARD. (``theta`` is reserved for
              the interaction parameters, so kernel hyperparameters are never called theta.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import cdist

from corl.errors import InputError
from corl.numerics import as_matrix

__all__ = ["SquaredExponential", "PAPER_LENGTHSCALE", "PAPER_SIGNAL_STD"]

#: Length scale and signal std used for both GPs on the synthetic problem (Sec. VIII-A).
PAPER_LENGTHSCALE = 0.4
PAPER_SIGNAL_STD = 10.0


@dataclass(frozen=True, eq=False)
class SquaredExponential:
    """Squared exponential kernel with automatic relevance determination (Eq. 16).

    ``k(x, x') = sf^2 exp(-0.5 (x - x')^T Lambda^{-1} (x - x'))`` with ``Lambda = diag(l^2)``.

    Parameters
    ----------
    lengthscales : float or (m,)
        One shared length scale, or one per input dimension (ARD). Must be positive.
    signal_std : float
        Signal standard deviation ``sf``; must be positive.

    Examples
    --------
    >>> k = SquaredExponential(0.4, 10.0)
    >>> k(np.zeros((1, 1))).item()
    100.0
    """

    lengthscales: np.ndarray | float = PAPER_LENGTHSCALE
    signal_std: float = PAPER_SIGNAL_STD

    def __post_init__(self) -> None:
        l = np.atleast_1d(np.asarray(self.lengthscales, dtype=float)).copy()
        if l.ndim != 1 or l.size == 0:
            raise InputError(f"lengthscales must be a positive number or a vector (m,), got shape {l.shape}")
        if not np.all(np.isfinite(l)) or np.any(l <= 0):
            raise InputError(f"lengthscales must be positive and finite, got {l}")
        sf = float(self.signal_std)
        if not np.isfinite(sf) or sf <= 0:
            raise InputError(f"signal_std must be positive and finite, got {self.signal_std}")
        l.setflags(write=False)
        object.__setattr__(self, "lengthscales", l)
        object.__setattr__(self, "signal_std", sf)

    # -- hyperparameters -----------------------------------------------------------------------
    @property
    def ard(self) -> bool:
        """True when every input dimension has its own length scale."""
        return self.lengthscales.size > 1

    @property
    def n_params(self) -> int:
        """Length of :attr:`log_params`."""
        return self.lengthscales.size + 1

    @property
    def log_params(self) -> np.ndarray:
        """``[log l_1, ..., log l_p, log sf]``, shape (p + 1,)."""
        return np.append(np.log(self.lengthscales), np.log(self.signal_std))

    def with_log_params(self, log_params) -> "SquaredExponential":
        """A new kernel with the given log hyperparameters (the kernel itself is immutable).

        Parameters
        ----------
        log_params : (p + 1,) in the order of :attr:`log_params`.
        """
        v = np.asarray(log_params, dtype=float).reshape(-1)
        if v.shape != (self.n_params,):
            raise InputError(
                f"log_params has shape {v.shape}, expected ({self.n_params},) = "
                f"{self.lengthscales.size} log length scale(s) followed by log signal_std"
            )
        if not np.all(np.isfinite(v)):
            raise InputError(f"log_params must be finite, got {v}")
        return SquaredExponential(np.exp(v[:-1]), float(np.exp(v[-1])))

    def __repr__(self) -> str:
        l = self.lengthscales
        ls = f"{l[0]:.4g}" if l.size == 1 else np.array2string(l, precision=4)
        return f"SquaredExponential(lengthscales={ls}, signal_std={self.signal_std:.4g})"

    # -- evaluation ----------------------------------------------------------------------------
    def _scaled(self, X, name: str) -> np.ndarray:
        """``X / l`` after checking shapes; returns (a, m)."""
        m = self.lengthscales.size if self.ard else None
        X = as_matrix(X, m, name=name)
        return X / self.lengthscales

    def __call__(self, X, Y=None) -> np.ndarray:
        """Covariance matrix between the rows of ``X`` (a, m) and ``Y`` (b, m); Y defaults to X.

        Returns
        -------
        K : (a, b)
        """
        A = self._scaled(X, "X")
        B = A if Y is None else self._scaled(Y, "Y")
        if A.shape[1] != B.shape[1]:
            raise InputError(f"X has {A.shape[1]} columns but Y has {B.shape[1]}; both need (., m)")
        if A.shape[0] == 0 or B.shape[0] == 0:
            return np.zeros((A.shape[0], B.shape[0]))
        # Eq. 16: squared Mahalanobis distance with Lambda = diag(l^2), then the exponential.
        # In place: fresh (a, b) temporaries cost more than the arithmetic for a large grid.
        K = cdist(A, B, "sqeuclidean")
        K *= -0.5
        np.exp(K, out=K)
        K *= self.signal_std**2
        return K

    def diag(self, X) -> np.ndarray:
        """``k(x, x)`` for every row of ``X`` (a, m); returns (a,), all equal to ``sf^2``."""
        A = self._scaled(X, "X")
        return np.full(A.shape[0], self.signal_std**2)

    def gradient(self, X) -> tuple[np.ndarray, np.ndarray]:
        """Gram matrix of ``X`` (a, m) and its derivatives with respect to :attr:`log_params`.

        Returns
        -------
        K : (a, a)
        dK : (p + 1, a, a), ``dK[j] = dK / d log_params[j]``:
            ``K * (x_j - x'_j)^2 / l_j^2`` for ARD length scales (summed over j for a shared one)
            and ``2 K`` for the signal std.
        """
        A = self._scaled(X, "X")
        a = A.shape[0]
        if a == 0:
            return np.zeros((0, 0)), np.zeros((self.n_params, 0, 0))
        sq = (A[:, None, :] - A[None, :, :]) ** 2  # (a, a, m), scaled squared differences
        K = self.signal_std**2 * np.exp(-0.5 * sq.sum(axis=2))
        dK = np.empty((self.n_params, a, a))
        if self.ard:
            dK[:-1] = np.moveaxis(sq, 2, 0) * K
        else:
            dK[0] = sq.sum(axis=2) * K
        dK[-1] = 2.0 * K
        return K, dK
