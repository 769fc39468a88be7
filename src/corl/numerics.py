"""Numerical helpers shared by the GP, acquisition and solver modules.

Glossary
--------
A      : symmetric positive (semi-)definite matrix, shape (d, d)
L      : lower Cholesky factor with L @ L.T = A + jitter * I
jitter : multiple of the mean diagonal added when a factorization fails
"""

from __future__ import annotations

import numpy as np
from scipy import linalg
from scipy.special import log_ndtr, ndtr

from corl.errors import InputError, NumericalError

__all__ = ["cholesky", "cho_solve", "floor_variance", "log_ndtr", "ndtr", "as_matrix", "as_vector"]

VARIANCE_FLOOR = 1e-12
_JITTER_LADDER = (0.0, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2)


def cholesky(A: np.ndarray, *, what: str = "matrix") -> tuple[np.ndarray, float]:
    """Lower Cholesky factor of ``A``, adding jitter on failure.

    Parameters
    ----------
    A : (d, d) symmetric matrix.
    what : name used in the error message (e.g. "GP regression Gram matrix").

    Returns
    -------
    L : (d, d) lower-triangular factor.
    jitter : the absolute jitter that was added to the diagonal (0.0 when none was needed).
    """
    A = np.asarray(A, dtype=float)
    if A.ndim != 2 or A.shape[0] != A.shape[1]:
        raise InputError(f"{what} must be square, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise NumericalError(f"{what} contains NaN or infinite entries; check the data and hyperparameters")
    scale = float(np.mean(np.abs(np.diag(A)))) if A.size else 1.0
    scale = scale if scale > 0 else 1.0
    for rel in _JITTER_LADDER:
        jitter = rel * scale
        try:
            L = linalg.cholesky(A + jitter * np.eye(A.shape[0]), lower=True, check_finite=False)
            return L, jitter
        except linalg.LinAlgError:
            continue
    raise NumericalError(
        f"{what} is not positive definite even with jitter {_JITTER_LADDER[-1]:g} x mean diagonal; "
        "remove duplicate inputs, raise the noise level or shorten the length scales"
    )


def cho_solve(L: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solve ``(L L^T) x = b`` for a lower factor ``L``; ``b`` is (d,) or (d, k)."""
    return linalg.cho_solve((L, True), b, check_finite=False)


def floor_variance(var: np.ndarray) -> np.ndarray:
    """Clip variances from below so that a square root or division stays finite."""
    return np.maximum(var, VARIANCE_FLOOR)


def as_vector(x, n: int | None = None, *, name: str = "x") -> np.ndarray:
    """Return ``x`` as a finite float vector of length ``n`` (any length when ``n`` is None)."""
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise InputError(f"{name} must be a vector, got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise InputError(f"{name} has shape {arr.shape}, expected ({n},)")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or infinite values: {arr}")
    return arr


def as_matrix(X, m: int | None = None, *, name: str = "X") -> np.ndarray:
    """Return ``X`` as a finite float matrix (d, m); a vector is read as d points in 1-D."""
    arr = np.asarray(X, dtype=float)
    if arr.ndim == 1:
        arr = arr.reshape(-1, 1) if (m in (None, 1)) else arr.reshape(1, -1)
    if arr.ndim != 2:
        raise InputError(f"{name} must be a (d, m) matrix, got shape {arr.shape}")
    if m is not None and arr.shape[1] != m:
        raise InputError(f"{name} has shape {arr.shape}, expected (d, {m})")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or infinite values")
    return arr
