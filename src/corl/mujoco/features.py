"""Eq. 6 features of a MuJoCo robot: ``q -> (y, dy/dq)`` callbacks for
:class:`corl.trajectory.TaskSpaceFeature`, with exact second derivatives.

Glossary
--------
q       (Q,) task configuration
y       (d,) a task-space quantity whose target the constraint ``h = y(xi(w, t_k)) - target_k``
        holds at the contact times t_k (Eq. 6)
dy/dq   (d, Q) its Jacobian; ``d2y/dq2`` (d, Q, Q) its Hessian (``H[a, i, j] = d2y_a / dq_i dq_j``)
weight  metres per radian: scales an orientation error so it can share ``h`` with positions

Each builder returns a :class:`Feature`: call it, ``fk(q) -> (y (d,), dy/dq (d, Q))``, and ask it
``fk.hessian(q)`` (d, Q, Q) for the curvature ``sum_i nu_i d2h_i`` of the solver's Newton-KKT
steps, which :class:`~corl.trajectory.TaskSpaceFeature` picks up by itself. :func:`stack` joins
several into one (values concatenated, Jacobians and Hessians stacked), so one
``TaskSpaceFeature(spline, stack(...), [t_k], target_k)`` constrains a whole pose at t_k.

One ``mj_kinematics`` per configuration gives value, Jacobian and (formed on demand, from the same
Jacobians: :mod:`corl.mujoco.kinematics`) Hessian; a feature keeps those of its last
:data:`CACHE_SIZE` configurations, keyed on the bytes of q, so the solver's value, Jacobian and
curvature calls at one iterate pose the robot once. (The key is q alone: a feature assumes its
model does not change under it.)
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from corl.errors import InputError
from corl.mujoco.kinematics import Frame, Kinematics, rotation_error, rotation_error_jacobian, rotation_error_second

__all__ = ["Feature", "position_feature", "orientation_feature", "coordinate_feature", "stack", "CACHE_SIZE"]

FK = Callable[[np.ndarray], "tuple[np.ndarray, np.ndarray]"]
Evaluate = Callable[[np.ndarray], "tuple[np.ndarray, np.ndarray, Callable[[], np.ndarray]]"]
CACHE_SIZE = 4  # configurations a feature remembers: its time's at the last iterates (the kit's tasks give each
# contact time its own feature; one fk shared by more times than this re-poses the robot for the curvature)


class Feature:
    """A task-space feature ``q -> (y (d,), dy/dq (d, Q))`` that also gives ``d2y/dq2`` (d, Q, Q).

    Parameters
    ----------
    evaluate : ``q -> (y, dy/dq, second)``, ``second()`` returning d2y/dq2 at that q (called on
        demand, at most once per cached configuration).
    dim : d (None when unknown).
    name : for messages.

    Every method returns fresh arrays (the cache keeps its own). A call answered from the cache
    does not pose the :class:`~corl.mujoco.Kinematics` it reads: use ``kin.set_q`` before reading
    ``kin.current_*``.
    """

    __slots__ = ("_evaluate", "dim", "name", "_cache")

    def __init__(self, evaluate: Evaluate, dim: int | None, name: str) -> None:
        self._evaluate, self.dim, self.name = evaluate, dim, name
        self._cache: dict[bytes, list] = {}

    def __repr__(self) -> str:
        return f"Feature({self.name}, d={self.dim})"

    def _entry(self, q) -> list:
        """``[y, dy/dq, second, d2y/dq2 or None]`` at q, from the cache or evaluated."""
        q = np.asarray(q, dtype=float)
        key = q.tobytes()
        entry = self._cache.get(key)
        if entry is None:
            entry = [*self._evaluate(q), None]
            if len(self._cache) >= CACHE_SIZE:  # first in, first out
                del self._cache[next(iter(self._cache))]
            self._cache[key] = entry
        return entry

    def _hessian(self, entry: list) -> np.ndarray:
        if entry[3] is None:
            entry[3], entry[2] = entry[2](), None  # the snapshot behind ``second`` is not needed again
        return entry[3]

    def __call__(self, q) -> tuple[np.ndarray, np.ndarray]:
        """``y`` (d,) and ``dy/dq`` (d, Q)."""
        entry = self._entry(q)
        return entry[0].copy(), entry[1].copy()

    def hessian(self, q) -> np.ndarray:
        """``d2y/dq2`` (d, Q, Q), exact (for the orientation's small-angle model, see there)."""
        return self._hessian(self._entry(q)).copy()

    def derivatives(self, q) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``y`` (d,), ``dy/dq`` (d, Q) and ``d2y/dq2`` (d, Q, Q) at once."""
        entry = self._entry(q)
        return entry[0].copy(), entry[1].copy(), self._hessian(entry).copy()


def position_feature(kin: Kinematics, frame: Frame) -> Feature:
    """``q -> (p (3,), dp/dq (3, Q))``: the frame's world position (the contact point of Eq. 6);
    ``hessian``: ``d2p/dq2`` (3, Q, Q), ``omega_min(a,b) x v_max(a,b)`` on the dofs (exact)."""

    def evaluate(q):
        kin.set_q(q)
        jacobians = kin.current_jacobians(frame)
        jp = jacobians.position_jacobian()
        return kin.current_position(frame), jp, lambda: jacobians.position_hessian(jp)

    return Feature(evaluate, 3, f"position of {frame.name}")


def orientation_feature(kin: Kinematics, frame: Frame, r_target: np.ndarray, *, weight: float = 1.0,
                        exact: bool = True) -> Feature:
    """``q -> (y (3,), dy/dq (3, Q))`` with ``y = -weight * rotation_error(r_target, R(q))``.

    ``y`` is zero when the frame has the orientation ``r_target`` (3, 3), and ``|y| / weight`` is the
    angle to it. Its target in a :class:`~corl.trajectory.TaskSpaceFeature` is zeros(3).

    Parameters
    ----------
    exact : the exact Jacobian ``weight J_r^{-1}(e) Jw`` (:func:`rotation_error_jacobian`) and the
        exact Hessian (:func:`~corl.mujoco.kinematics.rotation_error_second`). False: the
        small-angle Jacobian ``weight Jw``, exact at the target only (the classic resolved-rate
        Jacobian; Gauss-Newton still converges to ``y = 0``, more slowly far from it), and as
        Hessian the symmetric part of its derivative, ``weight (W + W^T) / 2`` - which is the exact
        Hessian at the target (e = 0), where ``d2(-e)/dtheta_a dtheta_b = omega_a x omega_b / 2``
        for a before b.
    """
    r_target = np.asarray(r_target, dtype=float)
    if r_target.shape != (3, 3) or not np.allclose(r_target @ r_target.T, np.eye(3), atol=1e-6):
        raise InputError(f"r_target must be a rotation matrix (3, 3), got shape {r_target.shape}")
    weight = float(weight)
    if not weight > 0:
        raise InputError(f"weight must be positive (metres per radian), got {weight}")

    def evaluate(q):
        kin.set_q(q)
        jacobians = kin.current_jacobians(frame)
        e = rotation_error(r_target, kin.current_rotation(frame))
        jw = jacobians.jacr[0]  # (3, m) over the dofs
        jac = jacobians.rotation_jacobian()
        jac = weight * (rotation_error_jacobian(e) @ jac) if exact else weight * jac

        def second():
            W = jacobians.angular_derivative()
            K = rotation_error_second(e, jw, W)[1] if exact else 0.5 * (W + np.swapaxes(W, 1, 2))
            return jacobians.to_task(weight * K, jac)

        return -weight * e, jac, second

    return Feature(evaluate, 3, f"orientation of {frame.name}")


def coordinate_feature(dim: int, index: int) -> Feature:
    """``q -> (q[index] (1,), e_index (1, dim))``: one coordinate of q, e.g. the gripper's; Hessian 0."""
    if not 0 <= index < dim:
        raise InputError(f"index {index} is outside q's {dim} coordinates")
    row = np.zeros((1, dim))
    row[0, index] = 1.0

    def evaluate(q):
        return q[index : index + 1].copy(), row, lambda: np.zeros((1, dim, dim))

    return Feature(evaluate, 1, f"q[{index}]")


def stack(*features: FK) -> FK:
    """One ``fk`` from several: values concatenated (sum d,), Jacobians stacked (sum d, Q).

    When every part gives second derivatives (a :class:`Feature`, or any callable with a
    ``hessian(q)`` method), the result is a :class:`Feature` whose Hessians are stacked
    (sum d, Q, Q); otherwise a plain function.
    """
    if not features or not all(callable(f) for f in features):
        raise InputError("stack() needs one or more callables q -> (y, dy/dq)")
    if not all(isinstance(f, Feature) or callable(getattr(f, "hessian", None)) for f in features):
        def fk(q):
            parts = [f(q) for f in features]
            return np.concatenate([np.atleast_1d(y) for y, _ in parts]), np.vstack([np.atleast_2d(j) for _, j in parts])

        return fk
    parts = [f._evaluate if isinstance(f, Feature) else _foreign(f) for f in features]

    def evaluate(q):
        outs = [part(q) for part in parts]
        y = np.concatenate([np.atleast_1d(o[0]) for o in outs])
        jac = np.concatenate([np.atleast_2d(o[1]) for o in outs])
        seconds = [o[2] for o in outs]
        return y, jac, lambda: np.concatenate([np.asarray(second(), dtype=float) for second in seconds])

    names = ", ".join(getattr(f, "name", getattr(f, "__name__", "fk")) for f in features)
    dims = [getattr(f, "dim", None) for f in features]
    return Feature(evaluate, None if None in dims else sum(dims), f"stack({names})")


def _foreign(f) -> Evaluate:
    """``evaluate`` of a callable with a ``hessian(q)`` method that is no :class:`Feature`."""

    def evaluate(q):
        q = q.copy()  # the caller's array may change before ``second`` runs
        y, jac = f(q)
        return np.asarray(y, dtype=float), np.asarray(jac, dtype=float), lambda: f.hessian(q)

    return evaluate
