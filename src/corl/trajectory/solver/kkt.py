"""Equality-constrained Newton (KKT) steps on a banded Hessian, inside the trust region of Eq. 8.

The SQP iteration of :mod:`corl.trajectory.solver.sqp` needs, at each iterate, the step ``d`` and the new
multipliers ``lam`` of the equality-constrained quadratic model

    min_d  g^T d + d^T H d / 2   s.t.  Jh d = -h,   ||u + d|| <= radius,

whose KKT conditions (Nocedal & Wright, Eq. 16.4, with the ball multiplier ``nu`` of More &
Sorensen 1983) are

    (H + nu I) d + Jh^T lam = -(g + nu u),   Jh d = -h,   nu >= 0,   nu (||u + d|| - radius) = 0.

H is banded (the k-order Markov cost of Eq. 7), ``Jh`` has few rows (start, goal and contact
constraints: q ~ 17), so the KKT system is solved by the Schur complement on one banded Cholesky
factor ``H + nu I = L L^T`` (N&W Sec. 16.2, the range-space method)::

    W = L^{-1} Jh^T (n, q),   S = W^T W = Jh (H + nu I)^{-1} Jh^T (q, q),
    v = L^{-1} b,   lam = S^{-1} (c - W^T v),   d = -L^{-T} (v + W lam)

for ``(H + nu I) d + Jh^T lam = -b``, ``Jh d = -c``: one ``dpbtrf``, forward substitutions for
the columns of W (each from its first non-zero row on) and one solve per right-hand side,
``O(n u^2 + q n u)``: linear in n. Two refinements keep it near one banded Cholesky:

* rows of Jh that fix one parameter (the start and goal of a clamped B-spline) are eliminated as
  Dirichlet rows before the factorization (:class:`~corl.trajectory.solver.factor.KKTStructure`):
  W and S are formed for the contact rows only;
* when the rest of the constraints touch one window of columns and H is the cost's constant
  ``H_J`` plus blocks on it (:class:`~corl.trajectory.solver.banded.BandedSum`), the band is
  condensed on that window (:mod:`corl.trajectory.solver.condense`): the two sides are
  factorized once per shift, and an iteration factorizes only the small Schur complement.

When the step leaves the ball, ``nu > 0`` solves ``||u + d(nu)|| = radius``. The new offset
``z = u + d`` splits into ``z_min``, the min-norm point of ``Jh z = Jh u - h`` in range(Jh^T)
(independent of nu), and an orthogonal part in null(Jh) of norm ``||y_null(nu)||``, the secular
function of the reduced trust-region problem. So More & Sorensen's Newton iteration on
``1 / ||y_null|| - 1 / r_null`` with ``r_null^2 = radius^2 - ||z_min||^2`` raises nu monotonically
from a shift where the step is too long; its derivative needs one more KKT solve. When H itself
is indefinite (constraint curvature), the iteration starts from a shift that makes it definite
and bisects away from indefinite shifts; when the boundary is not reached above them (the hard
case) there is no step (:class:`IndefiniteHessian`). When ``||z_min|| >= radius`` the linearized
constraints cannot be met inside the ball (:class:`Unreachable`).

Glossary
--------
H        : (n, n) :class:`~corl.trajectory.solver.banded.BandedSPD` or ``BandedSum``, the Hessian of the
           Lagrangian (plus ``2 mu Jh^T Jh``); ``H + nu I`` must be positive definite
g, b, c  : (n,) gradient of the model; right-hand sides (n,) and (q,) of a KKT solve
h        : (q,) constraint values;  Jh: their Jacobian, given on its support as ``Js`` (q, s)
           with ``Jh[:, support] = Js`` and zeros elsewhere
nu       : multiplier of the ball ``||u + d|| <= radius`` (a shift of H)
u, z     : offsets from the ball's center of the current point and of the new point, (n,)
L, W, S  : banded Cholesky factor of ``H + nu I``, ``L^{-1} Jh^T`` (n, q), Schur complement (q, q)
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.linalg.blas import dtbsv
from scipy.linalg.lapack import dpotrf, dpotrs, dtbtrs

from corl.trajectory.solver.banded import BandedSPD, BandedSum
from corl.trajectory.solver.condense import (
    CondensedFactor,
    NotCondensable,
    build_sides,
    find_sides,
    from_sides,
    window_block,
    window_of,
)
from corl.trajectory.solver.factor import IndefiniteHessian, KKTStructure, StepFailure, factorize, structure_of

__all__ = ["StepFailure", "IndefiniteHessian", "Unreachable", "KKTStructure", "KKTSystem", "structure_of", "constrained_step"]

_DEGENERATE = 1e-14  # S or Jh Jh^T is singular when its smallest pivot^2 is below this x its largest diagonal
_SECULAR_TOL = 1e-12  # relative accuracy of ||z|| = radius, as corl.trajectory.solver.linalg
_SECULAR_MAX_ITER = 50
_REACH_MARGIN = 1e-6  # the ball must leave this fraction of radius^2 to the null-space part of the step
_MAX_INDEFINITE = 2  # indefinite shifts met in the ball iteration before it gives up (the hard case)
_STALL_LIMIT = 2  # Newton steps on nu without getting closer to ||z|| = radius before the ball iteration stops


class Unreachable(StepFailure):
    """The linearized constraints ``Jh d = -h`` have no solution inside the ball."""


class KKTSystem:
    """The KKT matrix ``[[H + shift I, Jh^T], [Jh, 0]]``, factorized by the Schur complement.

    Rows of Jh that fix one parameter are eliminated first (:class:`~corl.trajectory.solver.factor.KKTStructure`).
    With the reduced
    ``H + shift I = L L^T`` (banded) and ``W = L^{-1} Jh_R^T`` (n, r) for the r other rows, the
    Schur complement is ``S = W^T W`` and a solve needs one forward and one backward substitution
    with L. Each column of ``Jh_R^T`` is zero above its first non-zero, and so is its column of W:
    W is kept from row ``k_W`` on, and the forward substitutions start there.

    Parameters
    ----------
    H : (n, n) banded Hessian, a :class:`~corl.trajectory.solver.banded.BandedSPD` or
        :class:`~corl.trajectory.solver.banded.BandedSum`; ``shift`` : multiple of the identity added to it (>= 0).
    support : (s,) sorted columns that ``Jh`` touches;  Js : (q, s) ``Jh[:, support]``.
    structure : the :class:`KKTStructure` of ``Js``'s pattern (computed from ``Js != 0`` if None).

    Raises
    ------
    IndefiniteHessian
        ``H + shift I`` (reduced) is not positive definite.
    StepFailure
        ``Jh`` has (numerically) dependent rows, so ``S`` is singular.
    """

    __slots__ = ("band", "k_W", "W", "L", "st", "top", "fixed_H", "columns", "a_fixed", "Js_rest_fixed", "u", "cond")

    def __init__(self, H: BandedSPD | BandedSum, shift: float, support: np.ndarray, Js: np.ndarray,
                 structure: KKTStructure | None = None) -> None:
        if not Js.any(axis=1).all():
            raise StepFailure("a row of the constraint Jacobian dh/dw is zero here")
        st = self.st = KKTStructure(support, Js != 0.0) if structure is None else structure
        n, u = H.shape[0], H.bandwidth
        gather, valid, columns, zero, groups = st.maps(n, u, support)
        self.u, self.columns, self.cond = u, columns, None
        if st.fixed_rows.shape[0]:
            self.a_fixed = Js[st.fixed_rows, st.fixed_at]
            self.Js_rest_fixed = Js[st.rest_rows[:, None], st.fixed_at] if st.rest_touch_fixed else None  # (r, f)
        window = window_of(H, st, support, n, u) if type(H) is BandedSum else None
        sides = None if window is None else find_sides(st, H.base, shift, u)
        if sides is not None:  # condensation at a kept shift: no band at all
            M_CC, self.fixed_H, self.top = from_sides(sides, H, st, support, window)
            self._condense(sides, window, M_CC, Js)
            return
        band = H.band()  # a new (u + 1, n) array, factorized in place
        self.top = top = float(np.max(band[0])) + shift
        if shift:
            band[0] += shift
        if st.fixed_rows.shape[0]:  # Dirichlet rows: keep row f of H + shift I, then decouple it
            flat = band.T.reshape(-1)  # a view: band is Fortran-ordered
            self.fixed_H = flat[gather] * valid  # (f, 2u + 1)
            flat[zero] = 0.0
            band[0, st.fixed_cols] = top
        if window is not None:  # one constraint window: condense on it (corl.trajectory.solver.condense)
            try:
                sides = build_sides(st, H, shift, band, window, top, support, gather, valid)
            except NotCondensable:
                sides = None
            if sides is not None:
                self._condense(sides, window, window_block(band, *window), Js)
                return
        self.band = factorize(band, top)
        self._schur(Js, groups)

    def _condense(self, sides, window, M_CC, Js) -> None:
        st = self.st
        self.band = self.W = self.L = None
        self.cond = CondensedFactor(sides, window, M_CC, Js[st.rest_rows[:, None], st.rest_Js_cols], self.top)

    def _schur(self, Js: np.ndarray, groups: list) -> None:
        """``W = L^{-1} Jh_R^T`` from row ``k_W`` on, by forward substitutions from each group's first
        row, and the Cholesky factor of ``S = W^T W`` (N&W Sec. 16.2)."""
        st, band = self.st, self.band
        n = band.shape[1]
        self.W = self.L = None
        self.k_W = n
        if not groups:
            return
        k_W = self.k_W = groups[0][0]  # groups are sorted by where they start
        plan = _schur_plan(st, n, band.shape[0] - 1, Js.shape[1], groups)
        Js_flat = Js.ravel()
        if len(plan) == 1 and plan[0][5]:  # one group of all rows (in the group's order, as x comes out)
            k, _, _, dest, source, _ = plan[0]
            W = np.zeros((n - k, st.rest_rows.shape[0]), order="F")
            W.T.reshape(-1)[dest] = Js_flat[source]
            W = _substitute(band[:, k:], W, "N", True)
        else:
            W = np.zeros((n - k_W, st.rest_rows.shape[0]), order="F")
            for k, cols, m, dest, source, _ in plan:
                rhs = np.zeros((m, n - k))  # (m, n - k): the transpose of an F-ordered rhs
                rhs.reshape(-1)[dest] = Js_flat[source]
                W[k - k_W:, cols] = _substitute(band[:, k:], rhs.T, "N", True)
        self.W = W
        self.L = _cholesky_or_fail(np.dot(W.T, W), "the Schur complement Jh H^{-1} Jh^T")

    def solve(self, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(a (n,), lam (q,))`` with ``(H + shift I) a + Jh^T lam = -b`` and ``Jh a = -c``.

        Fixed rows: ``a_f = -c_i / a_i``; the rest: ``v = L^{-1} b'``, ``S lam_R = c' - W^T v``,
        ``a = -L^{-T} (v + W lam_R)`` with b', c' carrying the fixed columns; then the fixed rows'
        multipliers from row f: ``a_i lam_i = -((H + shift I) a + b + Jh_R^T lam_R)_f``.
        """
        st = self.st
        fixed = st.fixed_rows.shape[0]
        if fixed:
            d_fixed = -c[st.fixed_rows] / self.a_fixed
            b_red = np.bincount(self.columns.ravel(), (self.fixed_H * d_fixed[:, None]).ravel(), b.shape[0])
            b_red += b  # b + H[:, f] d_f on the free rows
            b_red[st.fixed_cols] = -self.top * d_fixed
            c_rest = c[st.rest_rows]
            if self.Js_rest_fixed is not None:
                c_rest = c_rest + np.dot(self.Js_rest_fixed, d_fixed)
        else:
            b_red, c_rest = b, c
        if self.cond is not None:
            a, lam_rest = self.cond.solve(b_red, c_rest)
            return self._fixed_rows(a, lam_rest, b, c, d_fixed) if fixed else (a, lam_rest)
        v = dtbsv(self.u, self.band, b_red, lower=1)
        if self.L is not None:
            k = self.k_W
            lam_rest, _ = dpotrs(self.L, c_rest - np.dot(v[k:], self.W), lower=1)
            v[k:] += np.dot(self.W, lam_rest)
        else:
            lam_rest = c_rest[:0]
        a = dtbsv(self.u, self.band, v, lower=1, trans=1, overwrite_x=1)
        np.negative(a, out=a)
        if not fixed:
            return a, lam_rest
        return self._fixed_rows(a, lam_rest, b, c, d_fixed)

    def _fixed_rows(self, a, lam_rest, b, c, d_fixed) -> tuple[np.ndarray, np.ndarray]:
        """The step on the fixed columns and the fixed rows' multipliers, from row f of the KKT equations."""
        st = self.st
        a[st.fixed_cols] = d_fixed
        lam = np.empty(c.shape[0])
        lam[st.rest_rows] = lam_rest
        row_f = np.einsum("ij,ij->i", self.fixed_H, a[self.columns])  # ((H + shift I) a)_f
        row_f += b[st.fixed_cols]
        if self.Js_rest_fixed is not None:
            row_f += np.dot(lam_rest, self.Js_rest_fixed)
        lam[st.fixed_rows] = -row_f / self.a_fixed
        return a, lam


def _schur_plan(st: KKTStructure, n: int, u: int, s: int, groups: list) -> list:
    """Per group of :meth:`KKTStructure.maps`, where its entries of ``Js`` (q, s) go in its
    right-hand side: ``[(k, columns of W (a slice when consecutive), m, dest, source, all rows)]``
    with ``rhs[dest] = Js.ravel()[source]`` for the Fortran-ordered rhs (n - k, m) flattened.
    Cached on ``st`` per band size and width (the groups' keys) and width s of Js."""
    key = ("schur", n, u, s)
    found = st._maps.get(key)
    if found is None:
        found = []
        for k, rows, offsets, at in groups:
            m = rows.shape[0]
            consecutive = np.array_equal(rows, np.arange(rows[0], rows[0] + m))
            dest = (offsets[:, None] + (n - k) * np.arange(m)[None, :]).ravel()  # rhs[offsets[a], b]
            source = (st.rest_rows[rows][None, :] * s + at[:, None]).ravel()  # Js[rest_rows[rows[b]], at[a]]
            cols = slice(int(rows[0]), int(rows[0]) + m) if consecutive else rows  # a slice writes W faster
            found.append((k, cols, m, dest, source, m == st.rest_rows.shape[0]))
        st._maps[key] = found
    return found


def _substitute(band: np.ndarray, rhs: np.ndarray, trans: str, overwrite: bool = False) -> np.ndarray:
    """``L^{-1} rhs`` (trans "N") or ``L^{-T} rhs`` ("T") for a lower banded L in band storage (LAPACK
    ``dtbtrs``); ``overwrite``: rhs (Fortran-ordered) may be overwritten with the result."""
    x, info = dtbtrs(band, rhs, uplo="L", trans=trans, overwrite_b=overwrite)
    if info != 0:
        raise IndefiniteHessian(f"the banded Cholesky factor is singular (dtbtrs info = {info})")
    return x


def _cholesky_or_fail(S: np.ndarray, what: str) -> np.ndarray:
    """Lower Cholesky factor of a small SPD matrix S (q, q); StepFailure when S is (nearly) singular."""
    L, info = dpotrf(S, lower=1, clean=1)
    top = max(S.diagonal().tolist(), default=0.0)
    if info != 0 or not top > 0.0 or min(L.diagonal().tolist()) ** 2 <= _DEGENERATE * top:
        raise StepFailure(f"{what} is singular: the constraint Jacobian dh/dw has dependent rows here")
    return L


def constrained_step(
    H: BandedSPD | BandedSum,
    g: np.ndarray,
    support: np.ndarray,
    Js: np.ndarray,
    h: np.ndarray,
    u: np.ndarray | None = None,
    radius: float = math.inf,
    *,
    nu_definite: float | Callable[[], float] = 0.0,
    nu_guess: float = 0.0,
    structure: KKTStructure | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, float]:
    """Solve ``min g^T d + d^T H d / 2  s.t.  Jh d = -h,  ||u + d|| <= radius`` (see the module docstring).

    Parameters
    ----------
    H : (n, n) banded; g : (n,); support : (s,); Js : (q, s); h : (q,).
    u : (n,) offset of the current point from the ball's center, or None for no ball.
    radius : the ball's radius (ignored when ``u`` is None).
    nu_definite : a shift that makes ``H + nu I`` positive definite (e.g. minus the smallest
        eigenvalue of the constraint curvature in H), or a callable that computes it (called only
        when needed), tried when neither ``nu_guess`` nor 0 makes H definite: with a
        ball the step is then its boundary point at a multiplier where ``H + nu I`` is definite
        (More & Sorensen); when there is none (the hard case) IndefiniteHessian is raised.
    nu_guess : a first guess of the ball's multiplier (the previous iterate's), tried first.
    structure : the :class:`KKTStructure` of ``Js``'s pattern (a problem's, cached), or None to
        derive it from ``Js != 0``.

    Returns
    -------
    d : (n,) the step;  lam : (q,) multipliers of ``Jh d = -h``;
    z : (n,) ``u + d`` on the ball's boundary when the ball is active, else None;
    nu : the ball's multiplier (0 when inactive).

    Raises
    ------
    StepFailure
        ``H`` is indefinite without a ball, or no boundary point has a definite shift
        (:class:`IndefiniteHessian`); ``Jh`` is rank-deficient; or the linearized constraints
        cannot be met inside the ball (:class:`Unreachable`).
    """
    if structure is None:
        structure = KKTStructure(support, Js != 0.0)
    if u is None:
        d, lam = KKTSystem(H, 0.0, support, Js, structure).solve(g, h)
        return d, lam, None, 0.0
    # A first definite shift: the guess, else 0 (no ball), else nu_definite; lo: the largest indefinite one.
    lo, kkt, failed, tried = 0.0, None, False, set()
    for nu in (nu_guess, 0.0, nu_definite):
        if callable(nu):  # the definite shift costs an eigen-decomposition: only when the first two failed
            nu = float(nu())
        if nu in tried or (failed and nu <= lo):  # tried, or less definite than a shift that failed
            continue
        tried.add(nu)
        try:
            kkt = KKTSystem(H, nu, support, Js, structure)
            break
        except IndefiniteHessian:
            lo, failed = max(lo, nu), True
    if kkt is None:
        raise IndefiniteHessian("the Hessian is indefinite and no trial shift makes it definite")
    d, lam = kkt.solve(g + nu * u, h)
    z = u + d
    zz = float(np.dot(z, z))
    if nu > 0.0 and zz < radius * radius and lo == 0.0 and nu == nu_guess:  # the step is short: try nu = 0
        try:
            kkt0 = KKTSystem(H, 0.0, support, Js, structure)
            kkt, nu = kkt0, 0.0
            d, lam = kkt.solve(g, h)
            z = u + d
            zz = float(np.dot(z, z))
        except IndefiniteHessian:
            pass
    if nu == 0.0 and zz <= radius * radius:
        return d, lam, None, 0.0
    zmin_sq = _min_norm_sq(support, Js, h, u, radius)
    return _boundary_step(H, g, support, Js, h, u, radius, zmin_sq, nu, kkt, z, lam, lo, structure)


def _min_norm_sq(support, Js, h, u, radius: float) -> float:
    """``||z_min||^2 = t^T (Js Js^T)^{-1} t``, t = Jh u - h: the offset of the closest point of the
    linearized constraints from the center; Unreachable when it does not fit in the ball."""
    t = np.dot(Js, u[support]) - h
    G = _cholesky_or_fail(np.dot(Js, Js.T), "the normal matrix Jh Jh^T")
    zmin_sq = float(np.dot(t, dpotrs(G, t, lower=1)[0]))
    if zmin_sq >= (1.0 - _REACH_MARGIN) * radius * radius:
        raise Unreachable(
            f"the linearized constraints need a step to distance {math.sqrt(zmin_sq):.3g} from the center, "
            f"beyond the trust region's radius {radius:g}"
        )
    return zmin_sq


def _boundary_step(H, g, support, Js, h, u, radius, zmin_sq, nu, kkt, z, lam, lo, structure):
    """More & Sorensen's safeguarded Newton iteration on ``1/||y_null(nu)|| - 1/r_null`` (module
    docstring) from a definite ``nu`` with its KKT solve ``(kkt, z, lam)``; ``||z(nu)||`` falls as
    nu grows. ``lo``/``hi`` bracket the root: below lo the step is too long or H + nu I indefinite
    (``lo`` comes in as the largest indefinite shift met, or 0).
    From a start where the step is too long the iterates rise monotonically and stay definite;
    from one where it is too short, a Newton step may cross into the indefinite shifts, which are
    bisected away at most ``_MAX_INDEFINITE`` times before giving up (IndefiniteHessian)."""
    r_null = math.sqrt(radius * radius - zmin_sq)
    zero = np.zeros(h.shape[0])
    hi, indefinite = math.inf, 0
    zz = float(np.dot(z, z))
    best = (math.inf, z, lam, nu)  # (| ||z|| - radius |, z, lam, nu) of the closest point so far
    stalled = 0
    for _ in range(_SECULAR_MAX_ITER):
        zn = math.sqrt(zz)
        miss = abs(zn - radius)
        if miss <= _SECULAR_TOL * radius:
            break
        # Near the root, rounding in the KKT solves can keep ||z|| a few ulps of the tolerance away
        # while nu no longer moves: stop after _STALL_LIMIT Newton steps that did not get closer.
        if miss < best[0]:
            best, stalled = (miss, z, lam, nu), 0
        else:
            stalled += 1
            if stalled >= _STALL_LIMIT:
                _, z, lam, nu = best
                zz = float(np.dot(z, z))
                break
        if zn > radius:
            lo = nu
        else:
            hi = nu
        # Newton step; d||y_null||^2/dnu = 2 z^T dz/dnu, with dz/dnu from one more KKT solve.
        yn = math.sqrt(max(zz - zmin_sq, 1e-300))
        dz, _ = kkt.solve(z, zero)
        zq = -float(np.dot(z, dz))  # y_null^T (Z^T H Z + nu I)^{-1} y_null > 0
        nu = nu + (yn * yn / zq) * (yn - r_null) / r_null if zq > 0.0 else math.nan
        while True:  # keep nu inside the bracket and H + nu I definite
            if not (lo < nu < hi):
                if not math.isfinite(hi):
                    raise IndefiniteHessian("the trust-region multiplier has no Newton step")
                nu = 0.5 * (lo + hi)
            try:
                kkt = KKTSystem(H, nu, support, Js, structure)
                break
            except IndefiniteHessian:
                lo, indefinite = nu, indefinite + 1
                if indefinite > _MAX_INDEFINITE:
                    raise IndefiniteHessian(
                        "the trust-region step needs a shift at which the Hessian is indefinite (hard case)"
                    ) from None
        d, lam = kkt.solve(g + nu * u, h)
        z = u + d
        zz = float(np.dot(z, z))
    zn = math.sqrt(zz)
    if zn < radius * (1.0 - 1e-9):  # budget ran out on the short side
        raise IndefiniteHessian("the trust-region multiplier did not converge from above")
    if zn > radius:  # rounding, or the iteration budget ran out: onto the boundary
        z = z * (radius / zn)
    return z - u, lam, z, nu
