"""Task-space equality features on B-spline trajectories: Eq. 6, the contact-point projection.

``h_k = fk(xi(w, t_k)) - target_k`` at one contact time ``t_c`` or at several times of a contact
interval. Only the ``(degree + 1) Q`` parameters of the control points active at each ``t_k`` enter
a row of the Jacobian, so ``Jh^T Jh`` stays local and the Gauss-Newton matrix stays banded.

Glossary
--------
fk        : forward kinematics callback ``q (Q,) -> (y (d,), dy/dq (d, Q))``; optionally with a method
            ``fk.hessian(q) -> d^2 y / dq^2 (d, Q, Q)`` for the curvature (the kit's features have one)
nu        : (c d,) weights of ``sum_i nu_i d^2 h_i / dw^2``, the constraint curvature of a Newton-KKT step
t_k       : contact time(s), (c,); ``targets`` the task-space point(s) there, (c, d)
"""

from __future__ import annotations

import copy
from typing import Callable

import numpy as np
import scipy.sparse as sp

from corl.errors import InputError
from corl.trajectory.bspline import BSpline

__all__ = ["TaskSpaceFeature", "ForwardKinematics"]

ForwardKinematics = Callable[[np.ndarray], "tuple[np.ndarray, np.ndarray]"]
_FD_STEP = 1.5e-8  # relative forward-difference step for d^2 y / dq^2 (about sqrt of machine epsilon)


class TaskSpaceFeature:
    """Task-space points ``h_k = fk(xi(w, t_k)) - target_k`` at c times (Eq. 6).

    One time ``t_c`` is the contact-point projection ``h(w, theta) = phi_CP(xi(w, t_c)) - theta``;
    several times sample a contact interval ``[t_c0, t_c1]`` with one target each.

    Parameters
    ----------
    spline : the trajectory basis.
    fk : ``q (Q,) -> (y (d,), dy/dq (d, Q))``, forward kinematics and its Jacobian.
    times : (c,) contact times in [0, T].
    targets : (c, d) or (d,) task-space targets (one per time, or the same for all).
    fk_hessian : optional ``q (Q,) -> d^2 y / dq^2 (d, Q, Q)``. Default: ``fk.hessian`` when fk has
        one (the features of :mod:`corl.mujoco` do: exact, and from fk's cache at an iterate it
        has just evaluated); else :meth:`curvature` differentiates ``dy/dq`` by forward
        differences (Q extra calls of fk per time).

    Notes
    -----
    The value is (c d,) time-major. Only the ``(degree + 1) Q`` parameters of the control points
    active at each t_k enter its Jacobian row, so ``Jh^T Jh`` stays local (banded).
    """

    linear = False

    def __init__(self, spline: BSpline, fk: ForwardKinematics, times, targets, *, fk_hessian=None) -> None:
        if not callable(fk):
            raise InputError(f"fk must be callable q -> (y, dy/dq), got {fk!r}")
        if fk_hessian is not None and not callable(fk_hessian):
            raise InputError(f"fk_hessian must be callable q -> d2y/dq2 (d, Q, Q) or None, got {fk_hessian!r}")
        if fk_hessian is None and callable(getattr(fk, "hessian", None)):  # e.g. corl.mujoco's features
            fk_hessian = fk.hessian
        self.fk, self.fk_hessian, self.Q, self.n = fk, fk_hessian, spline.num_joints, spline.n
        B = spline.basis(times)
        c = B.shape[0]
        self.times = np.atleast_1d(np.asarray(times, dtype=float))
        targets = np.asarray(targets, dtype=float)
        if targets.ndim == 1:
            targets = np.broadcast_to(targets, (c, targets.shape[0]))
        if targets.ndim != 2 or targets.shape[0] != c or not np.all(np.isfinite(targets)):
            raise InputError(f"targets have shape {targets.shape}, expected finite (d,) or ({c}, d) for {c} times")
        self.targets = targets.copy()
        self.d = targets.shape[1]
        # The k + 1 basis functions active at each time: columns idx (c, k + 1) and values b (c, k + 1).
        width = spline.degree + 1
        B = B.tocsr()
        B.sort_indices()
        counts = np.diff(B.indptr)
        if np.any(counts > width):
            raise InputError("internal: a B-spline basis row has more than degree + 1 entries")
        idx = np.zeros((c, width), dtype=np.int64)
        val = np.zeros((c, width))
        for row in range(c):  # once, at construction
            cols = B.indices[B.indptr[row] : B.indptr[row + 1]]
            first = min(int(cols[0]) if cols.size else 0, spline.num_control_points - width)
            idx[row] = np.arange(first, first + width)
            val[row, cols - first] = B.data[B.indptr[row] : B.indptr[row + 1]]
        self.idx, self.basis_values = idx, val
        # Sparse pattern of the Jacobian: row (k, a) has columns idx[k, p] Q + j, p = 0..k, j = 0..Q-1.
        cols = (idx[:, :, None] * self.Q + np.arange(self.Q)).reshape(c, 1, width * self.Q)
        self._indices = np.broadcast_to(cols, (c, self.d, width * self.Q)).reshape(-1).astype(np.int32)
        self._indptr = (np.arange(c * self.d + 1) * (width * self.Q)).astype(np.int32)
        # For curvature: the columns of each time's block, (c, (degree + 1) Q), and b_k b_k^T
        # shaped (c, k + 1, 1, k + 1, 1) to broadcast against M_k into kron(b_k b_k^T, M_k).
        self._block_columns = cols.reshape(c, width * self.Q).astype(np.int64)
        self._basis_outer = (val[:, :, None] * val[:, None, :])[:, :, None, :, None]

    @property
    def dim(self) -> int:
        return self.targets.shape[0] * self.d

    def with_targets(self, targets) -> TaskSpaceFeature:
        """The same feature (fk, times, Jacobian pattern, fk's cache) at other targets, (c, d) or (d,):
        a shallow copy, nothing rebuilt (a task's Eq. 6 at a new theta moves only its targets)."""
        c = self.targets.shape[0]
        targets = np.asarray(targets, dtype=float)
        if targets.ndim == 1:
            targets = np.broadcast_to(targets, (c, targets.shape[0]))
        if targets.shape != self.targets.shape or not np.all(np.isfinite(targets)):
            raise InputError(f"targets have shape {targets.shape}, expected finite ({self.d},) or {self.targets.shape}")
        other = copy.copy(self)
        other.targets = targets.copy()
        return other

    def configurations(self, w: np.ndarray) -> np.ndarray:
        """``xi(w, t_k)`` (c, Q)."""
        W = w.reshape(-1, self.Q)
        return np.einsum("kp,kpj->kj", self.basis_values, W[self.idx])

    @property
    def columns(self) -> np.ndarray:
        """Columns of w that each Jacobian row touches, (c d, (degree + 1) Q), sorted per row."""
        return self._indices.reshape(self.dim, -1)

    def jacobian_rows(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``h`` (c d,) and the non-zeros of ``dh/dw`` on :attr:`columns`, (c d, (degree + 1) Q)."""
        X = self.configurations(w)
        c, d, Q = X.shape[0], self.d, self.Q
        values = np.empty((c, d))
        jac = np.empty((c, d, Q))
        for k in range(c):
            y, dy = self.fk(X[k])
            values[k] = np.asarray(y, dtype=float).reshape(d) - self.targets[k]
            jac[k] = np.asarray(dy, dtype=float).reshape(d, Q)
        # dh_k/dw[p Q + j] = b_kp dy_k/dq_j  (chain rule through xi(w, t_k) = B(t_k) W, Eq. 6)
        rows = (jac[:, :, None, :] * self.basis_values[:, None, :, None]).reshape(c * d, -1)
        return values.reshape(-1), rows

    def __call__(self, w: np.ndarray) -> tuple[np.ndarray, sp.csr_matrix]:
        values, rows = self.jacobian_rows(w)
        J = sp.csr_matrix((rows.reshape(-1), self._indices.copy(), self._indptr.copy()), shape=(self.dim, self.n))
        return values, J

    def curvature(self, w: np.ndarray, nu: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """``sum_i nu_i d^2 h_i / dw^2`` as blocks ``[(columns (s,), block (s, s)), ...]``, one per time.

        With ``M_k = sum_a nu_ka d^2 y_a / dq^2`` (Q, Q) at ``q_k = xi(w, t_k)``, the block on the
        ``(degree + 1) Q`` parameters active at ``t_k`` is ``kron(b_k b_k^T, M_k)`` (b_k: the basis
        values at t_k), since h is fk composed with the linear map w -> xi(w, t_k).
        """
        X = self.configurations(w)
        c = X.shape[0]
        nu = np.asarray(nu, dtype=float).reshape(c, self.d)
        M = np.empty((c, self.Q, self.Q))
        for k in range(c):  # M_k = sum_a nu_ka d^2 y_a / dq^2
            M[k] = self._weighted_hessian(X[k], nu[k])
        M = 0.5 * (M + np.swapaxes(M, 1, 2))
        # kron(b_k b_k^T, M_k) of every time at once, by broadcasting (np.kron's generic path costs more)
        s = self._block_columns.shape[1]
        blocks = (self._basis_outer * M[:, None, :, None, :]).reshape(c, s, s)
        return [(self._block_columns[k], blocks[k]) for k in range(c)]

    def _weighted_hessian(self, q: np.ndarray, nu: np.ndarray) -> np.ndarray:
        """``sum_a nu_a d^2 y_a / dq^2`` (Q, Q) at q (Q,): from ``fk_hessian``, or forward differences of
        ``nu^T dy/dq`` (column j is ``d(nu^T dy/dq)/dq_j``; Q extra calls of fk)."""
        if self.fk_hessian is not None:
            return np.tensordot(nu, np.asarray(self.fk_hessian(q), dtype=float).reshape(self.d, self.Q, self.Q), 1)
        base = nu @ np.asarray(self.fk(q)[1], dtype=float)
        eps = _FD_STEP * (1.0 + np.abs(q))
        M = np.empty((self.Q, self.Q))
        for j in range(self.Q):
            qj = q.copy()
            qj[j] += eps[j]
            M[:, j] = (nu @ np.asarray(self.fk(qj)[1], dtype=float) - base) / eps[j]
        return M
