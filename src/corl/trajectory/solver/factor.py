"""The banded factorization behind the KKT steps of :mod:`corl.trajectory.solver.kkt` (Eq. 8).

What depends only on the pattern of ``dh/dw`` is worked out once per problem, so that a step
costs little more than one banded Cholesky (LAPACK ``dpbtrf``, :func:`factorize`):

* :class:`KKTStructure`: which rows of ``dh/dw`` fix one parameter (the start and goal
  configurations of a clamped B-spline, Eq. 6); they are eliminated from the band as Dirichlet rows
  instead of joining the Schur complement. Built from the problem's constant pattern
  (:class:`~corl.trajectory.solver.banded.SupportPattern`), with the index maps of the band.
* :func:`start_groups`: the forward substitutions of the Schur complement start at each row's
  first non-zero.

Glossary
--------
n, u       : size and bandwidth of the (reduced) KKT Hessian in lower band storage ``ab`` (u + 1, n)
support    : (s,) sorted columns that ``Jh`` touches;  touched : (q, s) its structural non-zeros
fixed      : rows with one non-zero ``Jh[i, f] = a_i`` (Dirichlet rows) and their columns f
rest       : the other rows (contacts), whose Schur complement ``S = W^T W`` is formed
L          : the banded Cholesky factor
top        : largest diagonal entry of the matrix; a pivot^2 below ``1e-14 top`` counts as singular
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dpbtrf

from corl.errors import InputError
from corl.trajectory.solver.banded import SupportGram

__all__ = ["StepFailure", "IndefiniteHessian", "KKTStructure", "structure_of", "factorize", "start_groups"]

_DEGENERATE = 1e-14  # a pivot^2 below this x the largest diagonal entry: singular


class StepFailure(Exception):
    """No KKT step at this point (the SQP hands over to the augmented Lagrangian); ``str`` says why."""


class IndefiniteHessian(StepFailure):
    """``H + nu I`` is not positive definite (the constraint curvature outweighs the cost's)."""


class KKTStructure:
    """What the KKT solves reuse of the pattern of ``Jh`` (constant per problem, so built once).

    A row with one structural non-zero, ``Jh[i, f] = a_i`` (a fixed parameter: the start and goal
    configurations of a clamped B-spline, Eq. 6), fixes ``d_f = -c_i / a_i``; it is eliminated
    from the band as a Dirichlet row (row and column f of ``H + shift I`` zeroed, the pivot set to
    the matrix's scale, the known column moved to the right-hand side), and its multiplier follows
    from row f of the KKT equations afterwards. Only the other rows (the contact rows) need forward
    substitutions and the Schur complement.

    Parameters
    ----------
    support : (s,) sorted columns of ``Jh``;  touched : (q, s) bool, its structural non-zeros.
    """

    __slots__ = ("fixed_rows", "fixed_at", "fixed_cols", "rest_rows", "rest_first", "rest_last", "rest_Js_cols",
                 "rest_touch_fixed", "window", "sides", "_maps")

    def __init__(self, support: np.ndarray, touched: np.ndarray) -> None:
        fixed_rows, fixed_at = [], []
        for i in np.flatnonzero(touched.sum(axis=1) == 1).tolist():
            j = int(np.argmax(touched[i]))
            if j not in fixed_at:  # a second unit row on the same column stays (and makes S singular)
                fixed_rows.append(i)
                fixed_at.append(j)
        self.fixed_rows = np.asarray(fixed_rows, dtype=np.intp)
        self.fixed_at = np.asarray(fixed_at, dtype=np.intp)  # their columns' positions in support
        self.fixed_cols = support[self.fixed_at]
        self.rest_rows = np.setdiff1d(np.arange(touched.shape[0]), self.fixed_rows)
        rest = touched[self.rest_rows]
        self.rest_touch_fixed = bool(rest[:, self.fixed_at].any())  # a contact row on a fixed column
        rest[:, self.fixed_at] = False  # the eliminated columns are zero in the reduced rows
        self.rest_Js_cols = np.setdiff1d(np.arange(support.shape[0]), self.fixed_at)  # positions kept
        # first non-zero column of each reduced row (n for a row left empty: S is then singular)
        self.rest_first = np.where(rest.any(axis=1), support[np.argmax(rest, axis=1)], np.iinfo(np.intp).max)
        last = rest.shape[1] - 1 - np.argmax(rest[:, ::-1], axis=1) if rest.shape[1] else np.zeros(0, dtype=np.intp)
        self.rest_last = np.where(rest.any(axis=1), support[last] if rest.shape[1] else last, -1)  # its last one
        # the non-fixed columns, when one contiguous window (k, s): see corl.trajectory.solver.condense
        free = support[self.rest_Js_cols]
        contiguous = free.shape[0] and int(free[-1] - free[0]) + 1 == free.shape[0] and self.rest_rows.shape[0]
        self.window = (int(free[0]), int(free.shape[0])) if contiguous else None
        self.sides: list = []  # condense's factors of the two sides, per shift (most recent first)
        self._maps: dict = {}

    def maps(self, n: int, u: int, support: np.ndarray) -> tuple:
        """Index maps for a band (u + 1, n), cached: ``(gather, valid, columns, zero, groups)``.

        gather (f, 2u + 1): flat Fortran positions in ``ab`` of row ``fixed_cols[i]`` of H at the
        columns ``columns`` (f, 2u + 1) (``valid`` masks the ones outside the matrix); zero: flat
        positions of the off-diagonal band entries in the fixed rows and columns; groups: the forward
        substitutions of W, ``[(k, rows (into rest_rows), offsets (m,), positions in support (m,))]``
        sorted by k.
        """
        key = (n, u)
        found = self._maps.get(key)
        if found is None:
            found = self._maps[key] = self._build_maps(n, u, support)
        return found

    def _build_maps(self, n: int, u: int, support: np.ndarray) -> tuple:
        f = self.fixed_cols[:, None]
        offset = np.arange(-u, u + 1)[None, :]
        columns = f + offset
        valid = (columns >= 0) & (columns < n)
        columns = np.clip(columns, 0, n - 1)
        # H[f, c] is ab[f - c, c] below the diagonal (c <= f) and ab[c - f, f] above it
        gather = np.where(offset <= 0, columns * (u + 1) + (f - columns), f * (u + 1) + (columns - f))
        gather = np.where(valid, gather, 0)
        zero = np.unique(gather[valid & (offset != 0)])
        groups = []
        for k, rows in start_groups(self.rest_first, u):
            cols = support[self.rest_Js_cols]  # the group's rows touch columns k .. their last one only
            at = self.rest_Js_cols[(cols >= k) & (cols <= int(self.rest_last[rows].max()))]
            groups.append((k, rows, support[at] - k, at))
        return gather, valid.astype(float), columns, zero, groups


def structure_of(gram: SupportGram) -> KKTStructure:
    """The :class:`KKTStructure` of a constraint Gram's ``Js``: cached on the problem's
    :class:`~corl.trajectory.solver.banded.SupportPattern` when it has one, else from ``Js != 0``."""
    pattern = gram.pattern
    if pattern is None:
        return KKTStructure(gram.support, gram.Js != 0.0)
    found = pattern.derived.get("kkt")
    if found is None:
        found = pattern.derived["kkt"] = KKTStructure(pattern.support, pattern.touched)
    return found


def factorize(band: np.ndarray, top: float, start: int = 0) -> np.ndarray:
    """Banded Cholesky factor of ``band`` (u + 1, m), in place (LAPACK ``dpbtrf``); IndefiniteHessian
    when it fails or a pivot is at the rounding level of the largest diagonal entry ``top``
    (``start``: the column of the whole matrix where band begins, for the message)."""
    c, info = dpbtrf(band, lower=1, overwrite_ab=1)
    if info > 0:
        raise IndefiniteHessian(
            f"banded Cholesky of the Hessian of the Lagrangian failed at column {start + info - 1}: "
            "not positive definite (no jitter tried)"
        )
    if info < 0:
        raise InputError(f"banded Cholesky: argument {-info} had an illegal value (ab of shape {band.shape})")
    if float(np.min(c[0])) ** 2 <= _DEGENERATE * top:  # a rounding-level pivot: singular
        raise IndefiniteHessian("the Hessian of the Lagrangian is singular (a rounding-level Cholesky pivot)")
    return c


def start_groups(first: np.ndarray, width: int) -> list[tuple[int, np.ndarray]]:
    """Rows of Jh grouped by where they start: ``[(k, rows), ...]`` with every row of a group
    starting within ``width`` columns after k (one substitution per group; the few zero rows it
    adds cost less than a LAPACK call). Rows that start nowhere (eliminated entirely) are left out."""
    order = np.argsort(first, kind="stable")
    groups: list[tuple[int, list]] = []
    for i in order.tolist():
        if first[i] == np.iinfo(np.intp).max:
            continue
        if groups and first[i] < groups[-1][0] + max(width, 1):
            groups[-1][1].append(i)
        else:
            groups.append((int(first[i]), [i]))
    return [(k, np.asarray(rows, dtype=np.intp)) for k, rows in groups]
