"""Symmetric banded matrices and their Cholesky factorization (the k-order Markov structure of Eq. 7).

A cost of k-order Markov features on a B-spline trajectory (Eq. 7, Eq. 9) couples only control
points that are a few knots apart, so with the time-major layout ``w.reshape(P, Q)`` its
Gauss-Newton matrix ``H = 2 (Jr^T Jr + mu Jh^T Jh)`` is banded with a bandwidth of about
``(degree + 2) Q``; a constraint at one time ``t_c`` (Eq. 6) adds a dense block on the control
points active at ``t_c``, which lies inside the band. KOMO exploits the same structure. A banded
Cholesky (LAPACK ``dpbtrf``/``dpbtrs``) then costs ``O(n u^2)`` instead of ``O(n^3)``.

Glossary
--------
n         : size of the matrix
u         : bandwidth, the number of sub-diagonals: ``H[i, j] = 0`` when ``|i - j| > u``
ab        : LAPACK lower band storage, (u + 1, n), Fortran order (f2py would copy a C-order array
            at every LAPACK call): ``ab[i - j, j] = H[i, j]`` for ``0 <= i - j <= u``
support   : sorted column indices where a sparse Jacobian has entries, (s,)
G         : dense Gram matrix ``J[:, support]^T J[:, support]``, (s, s)
perm      : symmetric permutation (reverse Cuthill-McKee) applied before banding, (n,)
shift     : multiple of the identity added before factorizing (damping)
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.linalg.blas import dsbmv
from scipy.linalg.lapack import dpbtrf, dpbtrs
from scipy.sparse.csgraph import reverse_cuthill_mckee

from corl.errors import InputError, NumericalError

__all__ = ["BandedSPD", "BandedSum", "SupportPattern", "SupportGram", "BandedCholeskyFactor", "banded_cholesky", "bandwidth", "banded_ordering"]

_JITTER_LADDER = (1e-12, 1e-10, 1e-8, 1e-6, 1e-4)  # relative to the mean diagonal, as corl.numerics


class BandedSPD:
    """A symmetric (n, n) matrix in LAPACK lower band storage ``ab`` (u + 1, n).

    Supports what the Gauss-Newton solver needs: ``H @ x``, ``H.diagonal()``, ``c * H`` and
    ``H + c * SupportGram`` (which widens the band if the added block does not fit).
    """

    __slots__ = ("ab",)

    def __init__(self, ab: np.ndarray) -> None:
        self.ab = ab

    @property
    def shape(self) -> tuple[int, int]:
        n = self.ab.shape[1]
        return n, n

    @property
    def bandwidth(self) -> int:
        return self.ab.shape[0] - 1

    def diagonal(self) -> np.ndarray:
        """Main diagonal, (n,)."""
        return self.ab[0]

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        """``H x`` for x: (n,), by BLAS ``dsbmv``."""
        return dsbmv(self.ab.shape[0] - 1, 1.0, self.ab, x, lower=1)

    def __mul__(self, c: float) -> BandedSPD:
        return BandedSPD(np.asfortranarray(self.ab * c))

    __rmul__ = __mul__

    def __add__(self, other) -> BandedSPD:
        if type(other) is SupportGram:
            return other.added_to(self)
        if type(other) is BandedSPD:
            u = max(self.bandwidth, other.bandwidth)
            ab = _widened(self.ab, u)
            ab[: other.ab.shape[0]] += other.ab
            return BandedSPD(ab)
        return NotImplemented

    def band(self) -> np.ndarray:
        """A Fortran-ordered copy of the band storage (u + 1, n), to factorize in place."""
        return self.ab.copy(order="F")

    def toarray(self) -> np.ndarray:
        """Dense (n, n) copy (tests and debugging only)."""
        n, u = self.ab.shape[1], self.bandwidth
        H = np.zeros((n, n))
        for k in range(u + 1):
            idx = np.arange(n - k)
            H[idx + k, idx] = self.ab[k, : n - k]
            H[idx, idx + k] = self.ab[k, : n - k]
        return H

    @classmethod
    def from_sparse(cls, H, u: int | None = None) -> BandedSPD:
        """Band storage of a symmetric scipy.sparse (or dense) H (n, n); only the lower triangle is read.

        ``u`` defaults to the bandwidth of the sparsity pattern.
        """
        coo = sp.coo_matrix(H)
        n = coo.shape[0]
        if coo.shape != (n, n):
            raise InputError(f"a banded matrix must be square, got shape {coo.shape}")
        offset = coo.row - coo.col
        lower = offset >= 0
        offset, col, data = offset[lower], coo.col[lower], coo.data[lower]
        if u is None:
            u = int(offset.max()) if offset.size else 0
        elif offset.size and offset.max() > u:
            raise InputError(f"the matrix has entries {int(offset.max())} places below the diagonal, beyond u = {u}")
        ab = np.zeros((u + 1, n), order="F")
        key = offset.astype(np.int64) * n + col  # sum duplicates of the COO pattern, then scatter
        unique, inverse = np.unique(key, return_inverse=True)
        ab[unique // n, unique % n] = np.bincount(inverse, weights=data, minlength=unique.shape[0])
        return cls(ab)


class SupportPattern:
    """The structural non-zeros of a constraint Jacobian on its support: constant for a problem.

    A problem that gives its equalities on their support (``equalities_on_support``) builds one
    once; :class:`SupportGram` carries it, and the solver caches what it derives from it (band
    positions, the KKT elimination of :mod:`corl.trajectory.solver.kkt`) in :attr:`derived`.

    Attributes
    ----------
    support : (s,) sorted columns;  touched : (q, s) bool, the structural non-zeros of ``J[:, support]``.
    pairs : (rows, cols) of the lower triangle of ``J^T J`` on the support that some row touches.
    derived : dict, the solver's caches (keyed by name).
    """

    __slots__ = ("support", "touched", "pairs", "derived", "_batches")

    def __init__(self, support: np.ndarray, touched: np.ndarray) -> None:
        self.support, self.touched = support, touched
        t = touched.astype(float)
        self.pairs = np.nonzero(np.tril(t.T @ t))  # structural pattern of J^T J
        self.derived: dict = {}
        self._batches: list | None | bool = False  # gram()'s row groups (False: not worked out yet)

    def gram(self, Js: np.ndarray) -> np.ndarray:
        """``Js^T Js`` (s, s) for Js (q, s) with this pattern: rows that touch the same columns form a
        group, and each group's small ``B^T B`` (B: its rows on its columns) is added into place
        (one batched product per group size), instead of one dense product over every (zero) entry.
        The dense product when the groups would not save much."""
        batches = self._batches
        if batches is False:
            batches = self._batches = _row_batches(self.touched)
        if batches is None:
            return np.dot(Js.T, Js)
        s = Js.shape[1]
        parts = [np.matmul(B.transpose(0, 2, 1), B).ravel() for B in (Js[rows, cols] for rows, cols, _ in batches)]
        flat = self.derived.get("gram_flat")
        if flat is None:
            flat = self.derived["gram_flat"] = np.concatenate([f for _, _, f in batches])
        return np.bincount(flat, np.concatenate(parts) if len(parts) > 1 else parts[0], s * s).reshape(s, s)


def _row_batches(touched: np.ndarray) -> list | None:
    """Rows of a pattern (q, s) grouped by the columns they touch, batched by group size:
    ``[(rows (g, r, 1), cols (g, 1, c), flat (g c c,)), ...]`` (``Js[rows, cols]``: the groups' blocks
    (g, r, c); ``flat``: where their ``B^T B`` go in a raveled (s, s)); None when the groups cover
    more than a quarter of the dense product's work."""
    q, s = touched.shape
    if q == 0 or s == 0:
        return None
    keys, inverse = np.unique(touched, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    by_size: dict = {}
    for g in range(keys.shape[0]):
        rows, cols = np.flatnonzero(inverse == g), np.flatnonzero(keys[g])
        if cols.shape[0]:
            by_size.setdefault((rows.shape[0], cols.shape[0]), []).append((rows, cols))
    work = sum(len(groups) * r * c * c for (r, c), groups in by_size.items())
    if 4 * work > q * s * s:
        return None
    batches = []
    for groups in by_size.values():
        rows = np.stack([r for r, _ in groups])[:, :, None]
        cols = np.stack([c for _, c in groups])[:, None, :]
        flat = (cols.transpose(0, 2, 1) * s + cols).ravel()
        batches.append((rows, cols, flat))
    return batches


class SupportGram:
    """``scale * J^T J`` for a sparse J (q, n) with few non-zero columns, kept as a small dense block.

    The constraint part ``Jh^T Jh`` of the Gauss-Newton matrix (Eq. 8): its rows touch only the
    control points active at the constraint times, so it is stored as ``G`` (s, s) on ``support``.
    ``pattern`` is the problem's :class:`SupportPattern` when it has one (its caches are shared by
    every iterate), else None.
    """

    __slots__ = ("support", "G", "n", "pairs", "Js", "pattern")

    def __init__(self, support: np.ndarray, G: np.ndarray, n: int, pairs: tuple | None = None, Js=None,
                 pattern: SupportPattern | None = None) -> None:
        self.support, self.G, self.n, self.Js, self.pattern = support, G, n, Js, pattern
        # (rows, cols) of the lower-triangle entries of G that some row of J touches (the others
        # are structurally zero: a start and a goal constraint do not couple start and goal).
        if pairs is None:
            pairs = pattern.pairs if pattern is not None else np.nonzero((G != 0.0) & _lower_mask(G.shape[0]))
        self.pairs = pairs

    @classmethod
    def from_jacobian(cls, J, scale: float = 1.0) -> SupportGram:
        """From J: (q, n) scipy.sparse or ndarray; ``Js`` keeps ``J[:, support]`` (q, s) dense."""
        n = J.shape[1]
        if type(J) is np.ndarray:
            support = np.flatnonzero(np.any(J != 0.0, axis=0))
            Js = J[:, support]
        else:
            if J.format != "csr":
                J = J.tocsr()
            support = np.unique(J.indices)
            Js = np.zeros((J.shape[0], support.shape[0]))
            rows = np.repeat(np.arange(J.shape[0]), np.diff(J.indptr))
            np.add.at(Js, (rows, np.searchsorted(support, J.indices)), J.data)
        touched = (Js != 0.0).astype(float)
        pairs = np.nonzero(np.tril(touched.T @ touched))  # structural pattern of Js^T Js
        return cls(support, scale * (Js.T @ Js), n, pairs, Js)

    @classmethod
    def dense_block(cls, support: np.ndarray, G: np.ndarray, n: int) -> SupportGram:
        """A dense symmetric block G (s, s) on ``support``: every lower-triangle entry is added (zeros
        too), without a scan for non-zeros."""
        s = G.shape[0]
        pairs = _TRIL.get(s)
        if pairs is None:
            pairs = _TRIL[s] = np.tril_indices(s)
        return cls(support, G, n, pairs)

    @property
    def shape(self) -> tuple[int, int]:
        return self.n, self.n

    def diagonal(self) -> np.ndarray:
        """Diagonal entries on the support, (s,) (the others are 0)."""
        return np.diagonal(self.G)

    def __mul__(self, c: float) -> SupportGram:
        return SupportGram(self.support, c * self.G, self.n, self.pairs, self.Js, self.pattern)

    __rmul__ = __mul__

    def added_to(self, H: BandedSPD) -> BandedSPD:
        """A new :class:`BandedSPD` ``H + self`` (the band widens when the block does not fit)."""
        offset, columns, need = self._band_positions()
        ab = _widened(H.ab, max(need, H.bandwidth))
        rows, cols = self.pairs
        ab[offset, columns] += self.G[rows, cols]  # (offset, column) pairs are distinct
        return BandedSPD(ab)

    def add_into(self, H: BandedSPD) -> bool:
        """``H += self`` in place when the block fits in H's band; returns False (H untouched) if not."""
        offset, columns, need = self._band_positions()
        if need > H.bandwidth:
            return False
        rows, cols = self.pairs
        H.ab[offset, columns] += self.G[rows, cols]
        return True

    def _band_positions(self) -> tuple[np.ndarray, np.ndarray, int]:
        """(row in band storage, column) of each entry of :attr:`pairs`, both (len(pairs),), and the
        largest row; cached on the pattern when there is one."""
        if self.pattern is not None:
            found = self.pattern.derived.get("band_positions")
            if found is not None:
                return found
        s = self.support
        rows, cols = self.pairs  # lower triangle of the block (support is sorted)
        offset = s[rows] - s[cols]
        found = offset, s[cols], int(offset.max()) if offset.size else 0
        if self.pattern is not None:
            self.pattern.derived["band_positions"] = found
        return found

    def scatter(self, u: int) -> tuple[np.ndarray, np.ndarray]:
        """Flat positions of :attr:`pairs` in a Fortran-ordered band (u + 1, n) and in ``G.ravel()``
        (``band.T.reshape(-1)[positions] += G.ravel()[at]``); cached on the pattern when there is one."""
        key = ("scatter", u)
        if self.pattern is not None and key in self.pattern.derived:
            return self.pattern.derived[key]
        offset, columns, _ = self._band_positions()
        rows, cols = self.pairs
        found = columns * (u + 1) + offset, rows * self.G.shape[1] + cols
        if self.pattern is not None:
            self.pattern.derived[key] = found
        return found

    def covers(self, other: SupportGram) -> np.ndarray | None:
        """Where ``other``'s columns are in this block's support, (s_other,), when this block's pattern
        holds every pair of them (so ``other`` can be added into ``G`` and scattered with this block's
        pairs); None otherwise. Cached on the pattern per column set."""
        if self.pattern is None:
            return None
        key = ("covers", other.support.tobytes())
        found = self.pattern.derived.get(key, False)
        if found is False:
            found = None
            at = np.searchsorted(self.support, other.support)
            if at.shape[0] and at[-1] < self.support.shape[0] and np.array_equal(self.support[at], other.support):
                held = np.zeros((self.support.shape[0],) * 2, dtype=bool)
                held[self.pairs] = True
                lower = _lower_mask(at.shape[0])
                found = at if held[at[:, None], at][lower].all() else None
            self.pattern.derived[key] = found
        return found

    def toarray(self) -> np.ndarray:
        H = np.zeros((self.n, self.n))
        H[np.ix_(self.support, self.support)] = self.G
        return H


_TRIL: dict[int, tuple] = {}


class BandedSum:
    """``base + sum_k blocks_k``: a :class:`BandedSPD` plus dense blocks on few columns
    (:class:`SupportGram`), kept apart and added into band storage only when a factorization asks
    (:meth:`band`: one copy of the band per factorization, none for a product).

    The KKT Hessian of Eq. 8 is one: the constant ``H_J = 2 A^T A`` of the cost (Eq. 9) plus the
    constraint's ``2 mu Jh^T Jh`` and curvature on the contact columns (Eq. 6).
    """

    __slots__ = ("base", "blocks", "bandwidth")

    def __init__(self, base: BandedSPD, blocks: tuple) -> None:
        self.base, self.blocks = base, blocks
        self.bandwidth = max([base.bandwidth] + [block._band_positions()[2] for block in blocks])

    @property
    def shape(self) -> tuple[int, int]:
        return self.base.shape

    def band(self) -> np.ndarray:
        """The sum in band storage, a new Fortran-ordered (u + 1, n) array (widened when a block needs it)."""
        ab = _widened(self.base.ab, self.bandwidth)
        flat = ab.T.reshape(-1)  # a view: ab is Fortran-ordered
        for block in self.blocks:
            positions, at = block.scatter(self.bandwidth)
            flat[positions] += block.G.ravel()[at]  # the positions are distinct
        return ab

    def diagonal(self) -> np.ndarray:
        """Main diagonal, (n,)."""
        diag = self.base.ab[0].copy()
        for block in self.blocks:
            diag[block.support] += np.diagonal(block.G)
        return diag

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        """``(base + blocks) x`` for x: (n,): one ``dsbmv`` and a small product per block."""
        y = self.base @ x
        for block in self.blocks:
            y[block.support] += np.dot(block.G, x[block.support])
        return y

    def toarray(self) -> np.ndarray:
        """Dense (n, n) copy (tests and debugging only)."""
        return BandedSPD(self.band()).toarray()
_LOWER_MASKS: dict[int, np.ndarray] = {}


def _lower_mask(s: int) -> np.ndarray:
    """Boolean lower triangle (diagonal included) of an (s, s) matrix, cached per size."""
    mask = _LOWER_MASKS.get(s)
    if mask is None:
        mask = _LOWER_MASKS[s] = np.tri(s, dtype=bool)
    return mask


def _widened(ab: np.ndarray, u: int) -> np.ndarray:
    """Copy of ``ab`` with ``u + 1`` rows (zeros below)."""
    if ab.shape[0] == u + 1:
        return ab.copy(order="F")
    out = np.zeros((u + 1, ab.shape[1]), order="F")
    out[: ab.shape[0]] = ab
    return out


class BandedCholeskyFactor:
    """Banded Cholesky factor (``dpbtrf``) of ``P (H + shift I) P^T``, with an optional permutation.

    ``solve(b)`` returns ``(H + shift I)^{-1} b`` for b: (n,) or (n, k); ``jitter`` is what the
    jitter ladder of :func:`banded_cholesky` had to add to the diagonal (0.0 when nothing).
    """

    __slots__ = ("c", "perm", "inverse", "jitter")

    def __init__(self, c: np.ndarray, perm: np.ndarray | None = None, jitter: float = 0.0) -> None:
        self.c = c
        self.perm = perm
        self.jitter = jitter
        self.inverse = None if perm is None else np.argsort(perm)

    def solve(self, b: np.ndarray) -> np.ndarray:
        vector = b.ndim == 1
        rhs = b if self.perm is None else b[self.perm]
        x, info = dpbtrs(self.c, rhs[:, None] if vector else rhs, lower=1)
        if info != 0:
            raise InputError(f"banded solve: argument {-info} had an illegal value (b of shape {b.shape})")
        x = x[:, 0] if vector else x
        return x if self.inverse is None else x[self.inverse]


def banded_cholesky(
    ab: np.ndarray,
    shift: float = 0.0,
    *,
    perm: np.ndarray | None = None,
    what: str = "matrix",
    ladder: bool = True,
) -> BandedCholeskyFactor:
    """Factorize ``H + shift I`` given in lower band storage ``ab`` (u + 1, n) (LAPACK ``dpbtrf``).

    When the factorization fails (H not positive definite), a jitter ladder of ``1e-12 .. 1e-4``
    times the mean diagonal is added, as in :func:`corl.numerics.cholesky`; ``ladder=False`` skips
    the ladder (a caller that tests the inertia, as the SQP step of :mod:`corl.trajectory.solver.kkt`).

    Raises
    ------
    NumericalError
        If the matrix stays indefinite after the largest jitter (at once with ``ladder=False``).
    """
    for jitter in _jitters(ab) if ladder else (0.0,):
        shifted = ab.copy(order="F")
        if shift or jitter:
            shifted[0] += shift + jitter
        c, info = dpbtrf(shifted, lower=1, overwrite_ab=1)
        if info == 0:
            return BandedCholeskyFactor(c, perm, jitter)
        if info < 0:
            raise InputError(f"banded Cholesky: argument {-info} had an illegal value (ab of shape {ab.shape})")
    tried = f"even with jitter {_JITTER_LADDER[-1]:g} x mean diagonal" if ladder else "(no jitter tried)"
    raise NumericalError(
        f"banded Cholesky of the {what} failed: not positive definite {tried}; "
        "add damping or check that the Jacobians are finite"
    )


def _jitters(ab: np.ndarray):
    """0, then the jitter ladder relative to the mean |diagonal| (computed only when needed)."""
    yield 0.0
    scale = float(np.mean(np.abs(ab[0]))) if ab.shape[1] else 1.0
    scale = scale if scale > 0 and np.isfinite(scale) else 1.0
    for rel in _JITTER_LADDER:
        yield rel * scale


def bandwidth(H) -> int:
    """Bandwidth ``max |i - j|`` over the stored entries of a scipy.sparse H (n, n)."""
    coo = sp.coo_matrix(H)
    if coo.nnz == 0:
        return 0
    return int(np.abs(coo.row.astype(np.int64) - coo.col).max())


def banded_ordering(H) -> tuple[np.ndarray | None, int]:
    """The ordering of a sparse symmetric H (n, n) with the smaller bandwidth.

    Returns ``(perm, u)``: ``perm`` is None for the natural ordering (the time-major layout of the
    trajectory parameters already gives a band of about ``(degree + 2) Q``), else the reverse
    Cuthill-McKee permutation when it narrows the band.
    """
    u = bandwidth(H)
    n = H.shape[0]
    if (u + 1) * 4 <= n or n < 8:
        return None, u
    perm = reverse_cuthill_mckee(sp.csr_matrix(H), symmetric_mode=True).astype(np.int64)
    coo = sp.coo_matrix(H)
    position = np.empty(n, dtype=np.int64)
    position[perm] = np.arange(n)
    u_perm = int(np.abs(position[coo.row] - position[coo.col]).max()) if coo.nnz else 0
    return (perm, u_perm) if u_perm < u else (None, u)
