"""Shifted symmetric positive definite solves for the Gauss-Newton solver of Eq. 8.

Every linear solve of :mod:`corl.trajectory.solver` goes through :func:`factorize_spd`, so the
choice of factorization lives in one place: dense Cholesky for ``np.ndarray``; banded Cholesky
(LAPACK ``dpbtrf``, :mod:`corl.trajectory.solver.banded`) for a :class:`BandedSPD` and for
``scipy.sparse`` input whose bandwidth - in the natural ordering or after reverse Cuthill-McKee -
is below a quarter of n (long trajectories, k-order Markov structure of Eq. 7); a sparse LU on CSC
for other sparse input. No dense inverse is formed.
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
e, V   : eigenvalues (n,) and orthonormal eigenvectors (n, n) of a small dense H (n <= 16), in
         whose basis the ball subproblem is a scalar secular equation
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
from corl.trajectory.solver.banded import BandedCholeskyFactor, BandedSPD, banded_cholesky, banded_ordering

__all__ = [
    "SPDFactor",
    "DenseCholeskyFactor",
    "SparseLUFactor",
    "BandedCholeskyFactor",
    "BandedSPD",
    "factorize_spd",
    "solve_spd",
    "trust_region_step",
    "model_step",
]

_SECULAR_TOL = 1e-12  # relative accuracy of ||z|| = radius in the ball subproblem
_SECULAR_MAX_ITER = 50
_SMALL = 16  # dense H up to this size: one eigen-decomposition instead of repeated factorizations
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
    H : (n, n) ndarray, scipy.sparse matrix or :class:`BandedSPD`; only its lower triangle is read in
        the dense and banded cases. Sparse input with a small bandwidth (natural or reverse
        Cuthill-McKee ordering, ``(u + 1) * 4 <= n``) is factorized as a band, else by SuperLU.
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
    if type(H) is BandedSPD:
        return banded_cholesky(H.ab, shift, what=what)
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
    d, z, _, _ = model_step(H, g, damping, u, radius)
    return d, z


def model_step(
    H, g: np.ndarray, damping: float, u: np.ndarray | None = None, radius: float = math.inf
) -> tuple[np.ndarray, np.ndarray | None, float, float]:
    """:func:`trust_region_step`, plus ``||d||`` and the decrease ``-(g^T d + d^T H d / 2)`` of the
    undamped model that the step predicts (the solver's acceptance test needs both).

    Returns ``(d, z, step_norm, predicted)``. A dense H with n <= 16 is handled in its eigenbasis
    (one ``eigh``, scalar secular equation); larger or sparse ones by shifted factorizations. H may
    also be a nested list of floats and g a list (the solver's tiny problems, n <= 2).
    """
    if type(H) is list or (type(H) is np.ndarray and H.ndim == 2 and H.shape[0] <= _SMALL and H.shape[0] == H.shape[1]):
        return _small_model_step(H, g, damping, u, radius)
    d, z = _factorized_step(H, g, damping, u, radius)
    Hd = H @ d
    return d, z, math.sqrt(np.dot(d, d)), -(float(np.dot(g, d)) + 0.5 * float(np.dot(d, Hd)))


def _factorized_step(H, g, damping, u, radius) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`trust_region_step` by factorizations of ``H + shift I`` (any size, dense or sparse)."""
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


def _small_model_step(
    H, g, damping: float, u: np.ndarray | None, radius: float
) -> tuple[np.ndarray, np.ndarray | None, float, float]:
    """:func:`model_step` for a small dense H, in the eigenbasis ``H = V diag(e) V^T``.

    There ``(H + s I)^{-1}`` is diagonal, so the Newton iteration on the ball multiplier runs on
    Python floats: one eigen-decomposition replaces a factorization per iteration.
    """
    if type(H) is not list:
        H = H.tolist()
    if len(H) == 2:
        (a, _), (b, c) = H
        g0, g1 = g if type(g) is list else g.tolist()
        return _model_step_2d(a, b, c, g0, g1, damping, u, radius)
    e, V = _symmetric_eig(H)
    # Eigenvalues of the PSD H that rounding made negative count as 0; a zero shifted spectrum
    # (no damping, H singular) gets the smallest jitter of numerics.cholesky instead.
    shifted = [(ei if ei > 0.0 else 0.0) + damping for ei in e]
    if damping <= 0.0:
        top = max(shifted)
        floor = 1e-10 * (top if top > 0.0 else 1.0)
        shifted = [si if si > floor else floor for si in shifted]
    gt = _to_basis(V, g)  # V^T g
    if u is None:
        dt = [-gi / si for gi, si in zip(gt, shifted)]
        return _from_basis(V, dt), None, *_norm_and_decrease(dt, gt, e)
    ut = _to_basis(V, u)  # V^T u
    zt = [ui - gi / si for ui, gi, si in zip(ut, gt, shifted)]
    zz = sum(zi * zi for zi in zt)
    if zz <= radius * radius:
        dt = [zi - ui for zi, ui in zip(zt, ut)]
        return _from_basis(V, dt), None, *_norm_and_decrease(dt, gt, e)
    # Ball active: z(nu) = (H + (damping + nu) I)^{-1} b with b = (H + damping I) u - g; in the
    # eigenbasis z_i = b_i / (s_i + nu). Newton on 1/||z(nu)|| - 1/radius (More & Sorensen 1983)
    # raises nu monotonically from 0; zq = z^T (H + shift I)^{-1} z is the derivative's ingredient.
    bt = [si * ui - gi for si, ui, gi in zip(shifted, ut, gt)]
    nu = 0.0
    zn = math.sqrt(zz)
    for _ in range(_SECULAR_MAX_ITER):
        zq = 0.0
        for bi, si in zip(bt, shifted):
            zi = bi / (si + nu)
            zq += zi * zi / (si + nu)
        nu += (zz / zq) * (zn - radius) / radius
        if not math.isfinite(nu):
            raise NumericalError("the trust-region multiplier became NaN or inf; check that H and g are finite")
        zz = 0.0
        for bi, si in zip(bt, shifted):
            zi = bi / (si + nu)
            zz += zi * zi
        zn = math.sqrt(zz)
        if zn - radius <= _SECULAR_TOL * radius:
            break
    scale = radius / zn if zn > radius else 1.0
    zt = [scale * bi / (si + nu) for bi, si in zip(bt, shifted)]
    z = _from_basis(V, zt)
    dt = [zi - ui for zi, ui in zip(zt, ut)]
    return z - u, z, *_norm_and_decrease(dt, gt, e)


def _norm_and_decrease(dt: list, gt: list, e: list) -> tuple[float, float]:
    """``||d||`` and ``-(g^T d + d^T H d / 2)`` from eigenbasis coordinates (lists of floats)."""
    dd = decrease = 0.0
    for di, gi, ei in zip(dt, gt, e):
        dd += di * di
        decrease -= (gi + 0.5 * ei * di) * di
    return math.sqrt(dd), decrease


def _to_basis(V: np.ndarray, x) -> list:
    """``V^T x`` as a list; V: (n, n), x: (n,) ndarray or list."""
    return np.dot(x, V).tolist()


def _from_basis(V: np.ndarray, xt: list) -> np.ndarray:
    """``V xt`` (n,) from eigenbasis coordinates ``xt`` (list)."""
    return np.dot(V, xt)


def _symmetric_eig(H: list) -> tuple[list, np.ndarray]:
    """Eigenvalues (list of n floats) and orthonormal eigenvectors V (n, n) of a symmetric H
    (nested list), by LAPACK ``syevd`` through ``np.linalg.eigh``."""
    try:
        e, V = np.linalg.eigh(np.array(H, dtype=float))
    except np.linalg.LinAlgError as err:
        raise NumericalError(
            f"eigen-decomposition of the {_WHAT} failed ({err}); check that the Jacobians are finite"
        ) from err
    return e.tolist(), V


def _model_step_2d(
    a: float, b: float, c: float, g0: float, g1: float, damping: float, u: np.ndarray | None, radius: float
) -> tuple[np.ndarray, np.ndarray | None, float, float]:
    """:func:`model_step` for ``H = [[a, b], [b, c]]`` and ``g = (g0, g1)``, unrolled on floats.

    The synthetic benchmark (n = 2) takes this path thousands of times per run: a closed-form
    eigen-decomposition and the scalar secular equation, with no LAPACK call at all.
    """
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        raise NumericalError("the Gauss-Newton matrix contains NaN or inf; check the Jacobians")
    # Eigenpairs: e0 <= e1 with unit eigenvectors (x, y) for e1 and (-y, x) for e0.
    if b == 0.0:
        e0, e1, x, y = (a, c, 0.0, 1.0) if a <= c else (c, a, 1.0, 0.0)
    else:
        half, rad = 0.5 * (a - c), math.hypot(0.5 * (a - c), b)
        # Eigenvalue of larger magnitude without cancellation, the other from the determinant.
        if a + c >= 0.0:
            e1 = 0.5 * (a + c) + rad
            e0 = (a * c - b * b) / e1
        else:
            e0 = 0.5 * (a + c) - rad
            e1 = (a * c - b * b) / e0
        x, y = (half + rad, b) if half >= 0.0 else (b, rad - half)  # eigenvector of e1
        norm = math.hypot(x, y)
        x, y = x / norm, y / norm
    # Shifted spectrum, as in _small_model_step.
    s0 = (e0 if e0 > 0.0 else 0.0) + damping
    s1 = (e1 if e1 > 0.0 else 0.0) + damping
    if damping <= 0.0:
        floor = 1e-10 * (s1 if s1 > 0.0 else 1.0)
        s0, s1 = max(s0, floor), max(s1, floor)
    gt0, gt1 = x * g1 - y * g0, x * g0 + y * g1  # V^T g
    if u is None:
        ut0 = ut1 = 0.0
    else:
        u0, u1 = u.tolist()
        ut0, ut1 = x * u1 - y * u0, x * u0 + y * u1
    zt0, zt1 = ut0 - gt0 / s0, ut1 - gt1 / s1
    zz = zt0 * zt0 + zt1 * zt1
    ball = u is not None and zz > radius * radius
    if ball:
        # Newton on 1/||z(nu)|| - 1/radius with z_i = b_i / (s_i + nu) (More & Sorensen 1983).
        b0, b1 = s0 * ut0 - gt0, s1 * ut1 - gt1
        nu, zn = 0.0, math.sqrt(zz)
        for _ in range(_SECULAR_MAX_ITER):
            zq = zt0 * zt0 / (s0 + nu) + zt1 * zt1 / (s1 + nu)
            nu += (zz / zq) * (zn - radius) / radius
            if not math.isfinite(nu):
                raise NumericalError("the trust-region multiplier became NaN or inf; check that H and g are finite")
            zt0, zt1 = b0 / (s0 + nu), b1 / (s1 + nu)
            zz = zt0 * zt0 + zt1 * zt1
            zn = math.sqrt(zz)
            if zn - radius <= _SECULAR_TOL * radius:
                break
        if zn > radius:
            zt0, zt1 = zt0 * (radius / zn), zt1 * (radius / zn)
    dt0, dt1 = zt0 - ut0, zt1 - ut1
    dn = math.sqrt(dt0 * dt0 + dt1 * dt1)
    predicted = -((gt0 + 0.5 * e0 * dt0) * dt0 + (gt1 + 0.5 * e1 * dt1) * dt1)
    d = np.array([x * dt1 - y * dt0, y * dt1 + x * dt0])  # V dt
    if not ball:
        return d, None, dn, predicted
    z = np.array([x * zt1 - y * zt0, y * zt1 + x * zt0])
    return z - u, z, dn, predicted


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


def _factorize_sparse(H, shift: float, what: str) -> SparseLUFactor | BandedCholeskyFactor:
    n = H.shape[0]
    if H.shape != (n, n):
        raise InputError(f"{what} must be square, got shape {H.shape}")
    perm, u = banded_ordering(H)
    if (u + 1) * 4 <= n:  # banded Cholesky: O(n u^2), cheaper than SuperLU's fill-in here
        A = H if perm is None else sp.csr_matrix(H)[perm][:, perm]
        return banded_cholesky(BandedSPD.from_sparse(A, u).ab, shift, perm=perm, what=what)
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
