"""Static condensation of the KKT Hessian on the constraint window (Eq. 8 with one contact, Eq. 6).

The SQP's KKT Hessian is ``M = H_J + blocks + shift I`` after the Dirichlet rows of
:mod:`corl.trajectory.solver.factor`: the cost's constant banded ``H_J = 2 A^T A`` (Eq. 9) plus
``2 mu Jh^T Jh`` and the constraint curvature, which live on the few columns the contact touches.
When those columns form one window ``C = [k, k + s)``, the band splits into ``B1 = [0, k)``, C and
``B2 = [k + s, n)``, and B1 and B2 do not couple (they are more than u apart)::

    M = [[M11, E1^T-ish, 0], [., M_CC, .], [0, ., M22]],   M1C: rows of B1 within u of C (E1),
                                                            M2C: rows of B2 within u of C (E2)

M11 and M22 depend only on ``H_J`` and the shift: they are factorized once per shift (``M11 =
L1 L1^T`` from the top, ``M22`` from the bottom, i.e. ``J M22 J = L2 L2^T`` with J the reversal),
without the fill that the contact coupling causes in one band factorization. The Schur complement
on C needs only the corners of their inverses next to C, the inverses of the u x u trailing
blocks ``L1w``, ``L2w`` of the factors (a triangular matrix's trailing block of its inverse is the
inverse of its trailing block)::

    S = M_CC - T,   T = (L1w^{-1} E1)^T (L1w^{-1} E1) + (L2w^{-1} E2)^T (L2w^{-1} E2)     (s x s)

so an SQP iteration factorizes only the small dense S and the KKT system on C; a solve is one
forward and one backward substitution over B1 and B2 (N&W Sec. 16.2, block elimination).

Glossary
--------
n, u       : size and bandwidth of M in lower band storage ``ab`` (u + 1, n)
k, s       : the window C = [k, k + s);  m2 = n - k - s the length of B2
L1, L2     : band Cholesky factors of M11 (u + 1, k) and of the reversed M22 (u + 1, m2);
             U1, U2 their transposes in upper band storage (for the backward substitutions)
L1w, L2w   : their trailing u x u lower-triangular blocks (L2's in the reversed order)
E1, E2     : (u, s) ``M[B1 rows next to C, C]`` and ``M[B2 rows next to C, C]`` (E2 reversed, as L2)
Y          : ``[L1w^{-1} E1; L2w^{-1} E2]`` (2u, s), kept: ``T = Y^T Y``
S, Ls      : the Schur complement on C (s, s) and its Cholesky factor
Jc, Wc, Lc : the remaining constraint rows on C (r, s), ``Ls^{-1} Jc^T`` (s, r), chol(Wc^T Wc)
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import dtbsv, dtrsv
from scipy.linalg.lapack import dpbtrf, dpotrf, dpotrs, dtrtrs

from corl.trajectory.solver.factor import IndefiniteHessian, StepFailure

__all__ = ["CondensedFactor", "NotCondensable", "Sides", "window_of", "find_sides", "build_sides", "from_sides", "window_block"]

_DEGENERATE = 1e-14  # a pivot^2 below this x the largest diagonal entry: singular
_MAX_WINDOW = 256  # a larger window: one band factorization is cheaper than the dense Schur complement
_KEEP = 2  # side factors kept per problem (the SQP's shift 0 and the last ball shift)


class NotCondensable(Exception):
    """B1 or B2 alone is not positive definite: the direct band factorization decides."""


def window_of(H, st, support: np.ndarray, n: int, u: int) -> tuple[int, int] | None:
    """``(k, s)`` of the constraint window of a :class:`~corl.trajectory.solver.banded.BandedSum` H,
    or None when condensation does not apply: the non-fixed constraint columns are not one
    contiguous window (``st.window``), a block other than the constraints' Gram (on ``support``)
    reaches outside it, or either side is shorter than u."""
    if st.window is None:
        return None
    k, s = st.window
    if s > _MAX_WINDOW or k < u or n - k - s < u:
        return None
    for block in H.blocks:
        if block.support is not support and (block.support[0] < k or block.support[-1] >= k + s):
            return None
    return k, s


class Sides:
    """What condensation keeps per shift: the factors of M11 and M22, the constant part ``T`` of the
    Schur complement, and ``H_J + shift I`` where the iterates add to it (the window block, the
    eliminated rows, the diagonal), so that a later iterate at the same shift needs no band copy.
    Built by :func:`build_sides` from the reduced band of one iterate."""

    __slots__ = ("base", "shift", "L1", "L2", "U1", "U2", "Y", "T", "base_CC", "base_fixed_H", "base_diag",
                 "base_top", "fixed_scatter")


def find_sides(st, base, shift: float, u: int) -> Sides | None:
    """The problem's kept :class:`Sides` for this ``H_J``, shift and bandwidth, or None."""
    for sides in st.sides:
        if sides.base is base and sides.shift == shift and sides.L1.shape[0] == u + 1:
            return sides
    return None


def build_sides(st, H, shift: float, band: np.ndarray, window: tuple[int, int], top: float,
                support: np.ndarray, gather: np.ndarray, valid: np.ndarray) -> Sides:
    """Factorize the two sides of the reduced band (u + 1, n) and keep them on ``st`` (module docstring).

    Raises NotCondensable when a side is not positive definite alone."""
    k, s = window
    u = band.shape[0] - 1
    sides = Sides()
    sides.base, sides.shift = H.base, shift
    E1, E2 = _coupling(band, k, s)
    sides.L1 = _side_factor(band[:, :k].copy(order="F"), top)
    sides.L2 = _side_factor(_reversed(band[:, k + s:]), top)
    sides.U1, sides.U2 = _transposed(sides.L1), _transposed(sides.L2)  # L^T in upper storage: fast back-substitution
    # Y = Lw^{-1} E: E^T (M_BB^{-1} b)_near = Y^T (L^{-1} b)_trailing and L^{-1} (M_BC a_C) = Y a_C there
    sides.Y = np.vstack([_tri(_trailing(sides.L1, u), E1), _tri(_trailing(sides.L2, u), E2)])  # (2u, s)
    sides.T = np.dot(sides.Y.T, sides.Y)  # Y1^T Y1 + Y2^T Y2
    base = np.zeros((u + 1, band.shape[1]), order="F")  # H_J in the band's width
    base[: H.base.ab.shape[0]] = H.base.ab
    sides.base_CC = window_block(base, k, s) + shift * np.eye(s)
    sides.base_diag, sides.base_top = base[0], float(np.max(base[0]))
    sides.base_fixed_H = base.T.reshape(-1)[gather] * valid
    sides.base_fixed_H[:, u] += shift
    f = st.fixed_cols.shape[0]  # where the constraint Gram's rows of the fixed columns go in fixed_H
    offset = support[None, :] - st.fixed_cols[:, None]
    i, q = np.nonzero(np.abs(offset) <= u)
    sides.fixed_scatter = (i * (2 * u + 1) + offset[i, q] + u, st.fixed_at[i] * support.shape[0] + q) if f else None
    st.sides.insert(0, sides)
    del st.sides[_KEEP:]
    return sides


def from_sides(sides: Sides, H, st, support: np.ndarray, window: tuple[int, int]) -> tuple:
    """``(M_CC, fixed_H, top)`` of ``H + shift I`` at this iterate from the kept :class:`Sides` and the
    blocks of H: the window block (s, s), the eliminated rows (f, 2u + 1), the largest diagonal entry."""
    k, s = window
    M = sides.base_CC.copy()
    top = sides.base_top
    fixed_H = sides.base_fixed_H
    for block in H.blocks:
        top = max(top, max((sides.base_diag[block.support] + block.G.diagonal()).tolist()))
        if block.support is support:  # the constraints' Gram: its window and fixed rows
            at = st.rest_Js_cols
            M += block.G[at[:, None], at]
            if sides.fixed_scatter is not None:
                fixed_H = fixed_H.copy()
                fixed_H.reshape(-1)[sides.fixed_scatter[0]] += block.G.reshape(-1)[sides.fixed_scatter[1]]
        else:  # a block inside the window (window_of checked)
            at = block.support - k
            M[at[:, None], at] += block.G
    return M, fixed_H, top + sides.shift


class CondensedFactor:
    """The KKT system ``[[M, Jc^T], [Jc, 0]]`` with the rest rows ``Jc`` on the window, factorized by
    condensation (module docstring): the sides from :class:`Sides`, the window block ``M_CC`` of
    this iterate.

    Raises
    ------
    IndefiniteHessian
        the Schur complement S is not positive definite, so neither is M.
    StepFailure
        the constraint rows are (numerically) dependent.
    """

    __slots__ = ("k", "s", "sides", "Ls", "Wc", "Lc")

    def __init__(self, sides: Sides, window: tuple[int, int], M_CC: np.ndarray, Jc: np.ndarray, top: float) -> None:
        self.k, self.s = window
        self.sides = sides
        Ls, info = dpotrf(M_CC - sides.T, lower=1, clean=1)
        if info != 0 or min(Ls.diagonal().tolist()) ** 2 <= _DEGENERATE * top:
            raise IndefiniteHessian("the Hessian of the Lagrangian is not positive definite on the constraint window")
        self.Ls = Ls
        self.Wc = self.Lc = None
        if Jc.shape[0]:
            self.Wc = _tri(Ls, np.ascontiguousarray(Jc.T))
            Sc = np.dot(self.Wc.T, self.Wc)
            Lc, info = dpotrf(Sc, lower=1, clean=1)
            if info != 0 or min(Lc.diagonal().tolist()) ** 2 <= _DEGENERATE * max(Sc.diagonal().tolist()):
                raise StepFailure(
                    "the Schur complement Jh H^{-1} Jh^T is singular: the constraint Jacobian dh/dw has dependent rows here"
                )
            self.Lc = Lc

    def solve(self, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(a (n,), lam (r,))`` with ``M a + Jc^T lam = -b`` (Jc on the window) and ``Jc a_C = -c``."""
        k, s, sd = self.k, self.s, self.sides
        u = sd.L1.shape[0] - 1
        v1 = dtbsv(u, sd.L1, b[:k], lower=1)  # L1^{-1} b1
        v2 = dtbsv(u, sd.L2, b[:k + s - 1:-1], lower=1)  # L2^{-1} J b2
        # b_C - M_C1 M11^{-1} b1 - M_C2 M22^{-1} b2, with E^T Lw^{-T} = Y^T on the trailing entries
        bc = b[k:k + s] - np.dot(np.concatenate((v1[-u:], v2[-u:])), sd.Y)
        vc = dtrsv(self.Ls, bc, lower=1)
        if self.Lc is not None:
            lam, _ = dpotrs(self.Lc, c - np.dot(vc, self.Wc), lower=1)
            vc += np.dot(self.Wc, lam)
        else:
            lam = c[:0]
        ac = dtrsv(self.Ls, vc, lower=1, trans=1, overwrite_x=1)
        np.negative(ac, out=ac)
        # a_B = -M_BB^{-1} (b_B + M_BC a_C) = -L^{-T} (v + Y a_C on the trailing entries)
        t = np.dot(sd.Y, ac)
        v1[-u:] += t[:u]
        v2[-u:] += t[u:]
        a = np.empty(b.shape[0])
        a[:k] = dtbsv(u, sd.U1, v1, lower=0, overwrite_x=1)  # L1^{-T} by the upper-storage copy
        a[:k + s - 1:-1] = dtbsv(u, sd.U2, v2, lower=0, overwrite_x=1)
        np.negative(a, out=a)
        a[k:k + s] = ac
        return a, lam


def _side_factor(ab: np.ndarray, top: float) -> np.ndarray:
    """Band Cholesky factor of one side, in place; NotCondensable when it is not positive definite."""
    c, info = dpbtrf(ab, lower=1, overwrite_ab=1)
    if info != 0 or float(np.min(c[0])) ** 2 <= _DEGENERATE * top:
        raise NotCondensable("a side of the constraint window is not positive definite alone")
    return c


def _reversed(ab: np.ndarray) -> np.ndarray:
    """Lower band storage (u + 1, m) of ``J M J`` (J the reversal) from that of M: ``abR[i, j] =
    ab[i, m - 1 - j - i]``. Entries past the corner (``j + i >= m``) are not read by LAPACK and hold
    whatever the gather put there."""
    u, m = ab.shape[0] - 1, ab.shape[1]
    key = (u, m)
    index = _REVERSAL.get(key)
    if index is None:
        j, i = np.indices((m, u + 1))  # (m, u + 1): the transpose of the result, C-ordered
        index = _REVERSAL[key] = np.maximum(m - 1 - j - i, 0) * (u + 1) + i
    flat = ab.T.reshape(-1) if ab.flags.f_contiguous else np.asfortranarray(ab).T.reshape(-1)
    return flat[index].T  # Fortran-ordered (u + 1, m)


_REVERSAL: dict[tuple[int, int], tuple] = {}


def _transposed(L: np.ndarray) -> np.ndarray:
    """Upper band storage (u + 1, m) of ``L^T`` from the lower band storage of L: ``abU[u - i, c] =
    ab[i, c - i]``; BLAS's ``dtbsv`` substitutes with an upper matrix (by columns) about 2.5x faster
    than with the transpose of a lower one (by dot products). Entries before the corner (``c < i``)
    are not read."""
    u, m = L.shape[0] - 1, L.shape[1]
    key = (u, m)
    index = _TRANSPOSE.get(key)
    if index is None:
        c, r = np.indices((m, u + 1))  # row r of abU holds i = u - r
        i = u - r
        index = _TRANSPOSE[key] = np.maximum(c - i, 0) * (u + 1) + i
    return L.T.reshape(-1)[index].T  # Fortran-ordered (u + 1, m)


_TRANSPOSE: dict[tuple[int, int], tuple] = {}


def _trailing(L: np.ndarray, u: int) -> np.ndarray:
    """The trailing u x u lower-triangular block of a band factor L (u + 1, m), dense (Fortran)."""
    m = L.shape[1]
    i, j = np.tril_indices(u)
    out = np.zeros((u, u), order="F")
    out[i, j] = L[i - j, m - u + j]
    return out


def _coupling(band: np.ndarray, k: int, s: int) -> tuple[np.ndarray, np.ndarray]:
    """``E1 = M[k - u + i, k + j]`` and ``E2 = M[k + s + i', k + j]`` (u, s), E2's rows reversed
    (``i' = u - 1 - i``, the order of L2), from the lower band storage of M."""
    u = band.shape[0] - 1
    i, j = np.indices((u, s))
    # M[k + j, k - u + i] is band[u + j - i, k - u + i] when j <= i
    E1 = np.where(j <= i, band[np.clip(u + j - i, 0, u), k - u + i], 0.0)
    ir = u - 1 - i  # row k + s + ir of B2, at position i of the reversed order
    off = s + ir - j  # M[k + s + ir, k + j] is band[s + ir - j, k + j] when s + ir - j <= u
    E2 = np.where(off <= u, band[np.clip(off, 0, u), k + j], 0.0)
    return np.ascontiguousarray(E1), np.ascontiguousarray(E2)


def window_block(band: np.ndarray, k: int, s: int) -> np.ndarray:
    """``M[k:k+s, k:k+s]`` (s, s) dense from the lower band storage (zero beyond the bandwidth)."""
    u = band.shape[0] - 1
    i, j = np.indices((s, s))
    lo, hi = np.maximum(i, j), np.minimum(i, j)
    return np.where(lo - hi <= u, band[np.clip(lo - hi, 0, u), k + hi], 0.0)


def _tri(L: np.ndarray, B: np.ndarray) -> np.ndarray:
    """``L^{-1} B`` for a dense lower-triangular L (m, m) and B (m, p) (LAPACK ``dtrtrs``)."""
    X, info = dtrtrs(L, B, lower=1)
    if info != 0:
        raise IndefiniteHessian(f"a triangular factor is singular (dtrtrs info = {info})")
    return X
