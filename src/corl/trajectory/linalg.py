"""Shifted symmetric positive definite solves for the Gauss-Newton solver of Eq. 8.

Every linear solve of :mod:`corl.trajectory.solver` goes through :func:`factorize_spd`, so the
choice of factorization lives in one place: dense Cholesky for ``np.ndarray`` and a sparse LU on
CSC for ``scipy.sparse`` input. A banded Cholesky for long trajectories (n >= 1000, k-order Markov
structure of Eq. 7) can be added here without touching the solver. No dense inverse is formed.
:func:`trust_region_step` builds the solver's damped Gauss-Newton step inside the ball of Eq. 8
from these factorizations.

Glossary
--------
H      : symmetric positive semi-definite Gauss-Newton matrix, (n, n), ndarray or scipy.sparse
shift  : multiple of the identity added to H (Levenberg-Marquardt damping plus the multiplier of
         the trust-region ball), so the solves are with ``H + shift I``
factor : object whose ``solve(b)`` returns ``(H + shift I)^{-1} b`` for b: (n,)
g      : gradient, (n,)
u, z   : offsets from the ball's center of the current point and of the new point, (n,)
nu     : multiplier of the ball ``||z|| <= radius`` (eps_max of Eq. 8)
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
import scipy.sparse as sp
from scipy.linalg.lapack import dpotrf, dpotrs
from scipy.sparse.linalg import splu

from corl.errors import InputError, NumericalError
from corl.numerics import cholesky

__all__ = ["SPDFactor", "DenseCholeskyFactor", "SparseLUFactor", "factorize_spd", "solve_spd", "trust_region_step"]

_SECULAR_TOL = 1e-12  # relative accuracy of ||z|| = radius in the ball subproblem
_SECULAR_MAX_ITER = 50
_WHAT = "Gauss-Newton matrix of the augmented Lagrangian"


class SPDFactor(Protocol):
    """A factorization of ``H + shift I`` that can solve linear systems."""

    def solve(self, b: np.ndarray) -> np.ndarray:
        """Return ``x`` (n,) with ``(H + shift I) x = b``; ``b``: (n,)."""


class DenseCholeskyFactor:
    """Lower Cholesky factor ``L`` (n, n) of a dense SPD matrix; solves with LAPACK ``potrs``."""

    __slots__ = ("L",)

    def __init__(self, L: np.ndarray) -> None:
        self.L = L

    def solve(self, b: np.ndarray) -> np.ndarray:
        x, _ = dpotrs(self.L, b, lower=1)
        return x


class SparseLUFactor:
    """Sparse LU (SuperLU) of a CSC matrix, ordered for symmetric input."""

    __slots__ = ("lu",)

    def __init__(self, lu) -> None:
        self.lu = lu

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.lu.solve(b)


def factorize_spd(H, shift: float = 0.0, *, what: str = "Gauss-Newton matrix") -> SPDFactor:
    """Factorize ``H + shift I`` for a symmetric positive (semi-)definite ``H``.

    Parameters
    ----------
    H : (n, n) ndarray or scipy.sparse matrix; only its lower triangle is read in the dense case.
    shift : non-negative multiple of the identity to add (damping).
    what : name used in error messages.

    Returns
    -------
    factor : an :class:`SPDFactor`; ``factor.solve(b)`` solves ``(H + shift I) x = b``.

    Raises
    ------
    NumericalError
        If the shifted matrix is not positive definite even after the jitter ladder of
        :func:`corl.numerics.cholesky` (dense), or is exactly singular (sparse).
    """
    if type(H) is not np.ndarray and sp.issparse(H):  # the type test keeps small dense calls fast
        return _factorize_sparse(H, shift, what)
    return _factorize_dense(H, shift, what)


def solve_spd(H, b: np.ndarray, shift: float = 0.0, *, what: str = "Gauss-Newton matrix") -> np.ndarray:
    """Solve ``(H + shift I) x = b``; ``H``: (n, n) dense or sparse SPD, ``b``: (n,). Returns x: (n,)."""
    return factorize_spd(H, shift, what=what).solve(b)


def trust_region_step(
    H, g: np.ndarray, damping: float, u: np.ndarray | None = None, radius: float = math.inf
) -> tuple[np.ndarray, np.ndarray | None]:
    """Minimise ``g^T d + d^T (H + damping I) d / 2`` subject to ``||u + d|| <= radius``.

    The damped Gauss-Newton step of the solver, restricted to the trust region of Eq. 8.

    Parameters
    ----------
    H : (n, n) Gauss-Newton matrix, dense or sparse, positive semi-definite.
    g : (n,) gradient.
    damping : Levenberg-Marquardt shift, > 0 unless H is positive definite.
    u : (n,) offset of the current point from the ball's center (inside the ball), or None for no ball.
    radius : radius of the ball (ignored when ``u`` is None).

    Returns
    -------
    d : (n,) the step.
    z : (n,) the new offset ``u + d``, exactly on the boundary, when the ball is active; else None.
    """
    factor = factorize_spd(H, damping, what=_WHAT)
    d = -factor.solve(g)
    if u is None:
        return d, None
    z = u + d
    zn = math.sqrt(z @ z)
    if zn <= radius:
        return d, None
    # Ball active: (H + (damping + nu) I) z = (H + damping I) u - g with nu > 0 and ||z|| = radius.
    # Newton on 1/||z(nu)|| - 1/radius (More & Sorensen 1983) raises nu monotonically from 0.
    b = H @ u + damping * u - g
    nu = 0.0
    for _ in range(_SECULAR_MAX_ITER):
        q = factor.solve(z)  # z^T (H + shift I)^{-1} z gives the derivative of ||z(nu)||
        nu += (zn * zn / float(z @ q)) * (zn - radius) / radius
        if not math.isfinite(nu):
            raise NumericalError("the trust-region multiplier became NaN or inf; check that H and g are finite")
        factor = factorize_spd(H, damping + nu, what=_WHAT)
        z = factor.solve(b)
        zn = math.sqrt(z @ z)
        if zn - radius <= _SECULAR_TOL * radius:
            break
    if zn > radius:
        z = z * (radius / zn)
    return z - u, z


def _factorize_dense(H: np.ndarray, shift: float, what: str) -> DenseCholeskyFactor:
    if H.ndim != 2 or H.shape[0] != H.shape[1]:
        raise InputError(f"{what} must be square, got shape {H.shape}")
    n = H.shape[0]
    # One Fortran-ordered copy, shifted and then factorized in place by LAPACK.
    A = np.array(H, dtype=float, order="F")
    if shift:
        A.flat[:: n + 1] += shift
    L, info = dpotrf(A, lower=1, clean=0, overwrite_a=1)
    if info == 0:
        return DenseCholeskyFactor(L)
    if info < 0:  # pragma: no cover - LAPACK argument error, cannot happen with a square float array
        raise NumericalError(f"LAPACK potrf rejected argument {-info} while factorizing the {what}")
    # Not positive definite at this shift: fall back on the jitter ladder of numerics.cholesky.
    shifted = np.array(H, dtype=float)
    if shift:
        shifted.flat[:: n + 1] += shift
    L, _ = cholesky(0.5 * (shifted + shifted.T), what=what)
    return DenseCholeskyFactor(np.asfortranarray(L))


def _factorize_sparse(H, shift: float, what: str) -> SparseLUFactor:
    n = H.shape[0]
    if H.shape != (n, n):
        raise InputError(f"{what} must be square, got shape {H.shape}")
    A = sp.csc_matrix(H, dtype=float)
    if shift:
        A = (A + shift * sp.identity(n, format="csc")).tocsc()
    try:
        # Symmetric mode: minimum degree on A^T + A and diagonal pivots, the usual set-up for SPD
        # matrices in SuperLU.
        lu = splu(
            A,
            permc_spec="MMD_AT_PLUS_A",
            diag_pivot_thresh=0.0,
            options={"SymmetricMode": True},
        )
    except RuntimeError as err:
        raise NumericalError(
            f"sparse factorization of the {what} failed ({err}); the matrix is singular - add damping "
            "or check that the Jacobians are finite and not all zero"
        ) from err
    return SparseLUFactor(lu)
