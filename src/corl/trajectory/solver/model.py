"""The Gauss-Newton model of the augmented Lagrangian for :mod:`corl.trajectory.solver`.

One evaluation of the problem (:class:`Iterate`) and the gradient and Gauss-Newton Hessian of

    L_A(w) = r^T r + lam^T h + mu h^T h                 (N&W Framework 17.3, around Eq. 8)

built from it. Tiny dense problems (n = 2, a few rows: the synthetic benchmark, solved thousands
of times per run) are handled on Python floats, where numpy's per-call overhead would cost more
than the arithmetic; everything else on ndarrays or scipy.sparse.

Glossary
--------
w          : decision variables, (n,)
r, Jr      : cost residuals (p,) and their Jacobian dr/dw (p, n)
h, Jh      : equality constraints (q,) and their Jacobian dh/dw (q, n)
lam, mu    : multiplier estimate (q,) and penalty weight of L_A
g, H       : gradient (n,) and Gauss-Newton Hessian (n, n) of L_A
grams      : per-point cache ``(2 Jr^T r, 2 Jr^T Jr, 2 Jh^T Jh)``
affine     : ``(2 Jr^T Jr, 2 Jr^T b)`` given by a problem with affine residuals ``r = Jr w - b``, or None

A problem whose residuals are affine in w (linear features, Eq. 9) may offer ``affine_cost()``,
returning the constant Gauss-Newton Hessian ``2 Jr^T Jr`` (ndarray, scipy.sparse or
:class:`~corl.trajectory.solver.banded.BandedSPD`) and ``c = 2 Jr^T b`` (n,), so that the gradient of J is
``2 Jr^T Jr w - c``; or None. Neither is then recomputed at any iterate. With a banded Hessian,
``2 Jh^T Jh`` is kept as a :class:`~corl.trajectory.solver.banded.SupportGram` on the few columns the
constraints touch and H stays banded (factorized by LAPACK ``dpbtrf``).

A problem with such a banded cost may also offer ``equalities_on_support(w)``, returning ``h`` and
``dh/dw`` as a dense block on the few columns it touches (``(h, support, Js, pattern)``, see
:meth:`~corl.trajectory.features.TrajectoryProblem.equalities_on_support`) or None: then no
sparse Jh is built per iterate (``Iterate.Jh`` is None and ``Iterate.JhJh`` holds ``2 Jh^T Jh``).

A problem without equalities whose residuals are nonlinear but have a banded Jacobian (the phase
profile of Eq. 10) may offer ``gauss_newton_band(w)``, returning ``(r, 2 Jr^T r, 2 Jr^T Jr)`` with
the last a :class:`~corl.trajectory.solver.banded.BandedSPD`: the damped Gauss-Newton steps then
run on banded Cholesky factors with no Jacobian matrix built (``Iterate.Jr`` is None).

A problem may also offer ``equality_curvature(w, nu)``, returning ``sum_i nu_i d^2 h_i / dw^2``
(a :class:`~corl.trajectory.solver.banded.SupportGram`, ndarray or scipy.sparse, or None): the
Lagrangian curvature that Gauss-Newton drops. It is added to H with ``nu = lam + 2 mu h``, which
makes the steps on nonlinear constraints Newton steps (as Ipopt's exact Hessian); H may then be
indefinite, and the solver raises the damping until it factorizes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from corl.errors import InputError, NumericalError
from corl.trajectory.solver.banded import BandedSPD, SupportGram, SupportPattern

Jacobian = Any  # np.ndarray or scipy.sparse matrix, (rows, n)

NOISE = 8 * np.finfo(float).eps  # relative rounding level of L_A below which decreases are noise
_SMALL = 32  # vectors up to this length are reduced in Python (cheaper than a ufunc call)


@dataclass(slots=True, eq=False)
class Iterate:
    """The problem evaluated at one point ``w``: what every step strategy reads (shared by the
    augmented Lagrangian, :mod:`~corl.trajectory.solver.al`, and SQP, :mod:`~corl.trajectory.solver.sqp`).

    Attributes
    ----------
    w : (n,) the point.
    r, Jr : residuals (p,) and ``dr/dw`` (p, n), ndarray or scipy.sparse.
    h, Jh : constraints (q,) and ``dh/dw`` (q, n); ``Jh`` is None when the problem gave it on its
        support only (then ``JhJh`` holds ``2 Jh^T Jh``).
    rr, hh : ``r^T r`` (J, Eq. 7) and ``h^T h``.
    affine : ``(2 Jr^T Jr, 2 Jr^T b)`` of an affine cost (the problem's ``affine_cost()``), or None.
    curvature : the problem's ``equality_curvature`` (``(w, nu) -> sum_i nu_i d2h_i``), or None.
    JhJh : ``2 Jh^T Jh`` as a :class:`~corl.trajectory.solver.banded.SupportGram`, or None.
    AT : ``Jr^T`` (n, p) in CSR for an affine cost whose problem gives it (``affine_transpose()``),
        else None; the cost gradient is then ``2 Jr^T r`` instead of ``H_J w - c``.
    err : ``max |h|`` (0 without constraints); set from ``h``.
    grams : cache of ``(2 Jr^T r, 2 Jr^T Jr, 2 Jh^T Jh)``, filled by :func:`compute_grams` on first
        use and reused while only lam or mu change.
    """

    w: np.ndarray
    r: np.ndarray
    Jr: Jacobian
    h: np.ndarray
    Jh: Jacobian | None
    rr: float
    hh: float
    affine: tuple | None = None
    curvature: Callable | None = None
    JhJh: SupportGram | None = None
    AT: Any = None
    err: float = field(init=False)
    grams: tuple | None = field(default=None, init=False)

    def __post_init__(self) -> None:
        self.err = max_abs(self.h)


def checked_pair(pair, n: int, what: str, jac_name: str) -> tuple[np.ndarray, Jacobian]:
    """Validate one ``(value, Jacobian)`` return (done on every call; cheap)."""
    try:
        value, jac = pair
    except (TypeError, ValueError):
        raise InputError(f"{what} must return a pair (value, Jacobian), got {type(pair).__name__}") from None
    value = np.asarray(value, dtype=float)
    if value.ndim != 1:
        raise InputError(f"{what} returned a value of shape {value.shape}; expected a vector")
    if type(jac) is not np.ndarray and not sp.issparse(jac):
        jac = np.asarray(jac, dtype=float)
    if jac.shape != (value.shape[0], n):
        raise InputError(
            f"{what} returned {jac_name} of shape {jac.shape}, expected ({value.shape[0]}, {n}) "
            f"for a value of shape {value.shape} and w of shape ({n},)"
        )
    return value, jac


def non_finite_error(what: str, w: np.ndarray, hint: str) -> NumericalError:
    return NumericalError(
        f"{what} returned NaN or inf at w = {np.array2string(w, precision=6, threshold=8)}; {hint}"
    )


def evaluate_problem(problem, w: np.ndarray) -> Iterate:
    """The problem at ``w`` (n,): its residuals, equalities and what the strategies reuse."""
    n = w.shape[0]
    banded_gn = getattr(problem, "gauss_newton_band", None)
    if banded_gn is not None:
        pt = _evaluate_banded_gauss_newton(problem, w, banded_gn)
        if pt is not None:
            return pt
    r, Jr = checked_pair(problem.residuals(w), n, "residuals", "dr/dw")
    affine = getattr(problem, "affine_cost", None)
    affine = None if affine is None else affine()
    on_support = getattr(problem, "equalities_on_support", None)
    if affine is not None and type(affine[0]) is BandedSPD and on_support is not None:
        banded = _evaluate_on_support(problem, w, r, Jr, affine, on_support(w))
        if banded is not None:
            return banded
    h, Jh = checked_pair(problem.equalities(w), n, "equalities", "dh/dw")
    rr, hh = _finite_sumsq(r, h, w)
    if (type(Jr) is not type(Jh)) and h.shape[0] > 0 and sp.issparse(Jr) != sp.issparse(Jh):  # mixed: go sparse
        Jr, Jh = sp.csr_matrix(Jr), sp.csr_matrix(Jh)
    curvature = getattr(problem, "equality_curvature", None) if h.shape[0] else None
    return Iterate(w, r, Jr, h, Jh, rr, hh, affine, curvature)


def _evaluate_on_support(problem, w, r, Jr, affine, on_support) -> Iterate | None:
    """:func:`evaluate_problem` for a banded affine cost and equalities given as ``(h, support, Js, pairs)``
    (``equalities_on_support``): ``2 Jh^T Jh`` goes straight to a SupportGram, no sparse Jh is
    built. None when the problem could not give its equalities that way (or has none)."""
    if on_support is None:
        return None
    h, support, Js, pattern = on_support
    if h.shape[0] == 0:
        return None
    rr, hh = _finite_sumsq(r, h, w)
    if type(pattern) is SupportPattern:  # the problem's constant pattern: the solver's caches live on it
        JhJh = SupportGram(support, 2.0 * pattern.gram(Js), w.shape[0], pattern.pairs, Js, pattern)
    else:  # (rows, cols) of the structural non-zeros of Js^T Js
        JhJh = SupportGram(support, 2.0 * np.dot(Js.T, Js), w.shape[0], pattern, Js)
    curvature = getattr(problem, "equality_curvature", None)
    transpose = getattr(problem, "affine_transpose", None)
    return Iterate(w, r, Jr, h, None, rr, hh, affine, curvature, JhJh, None if transpose is None else transpose())


def _evaluate_banded_gauss_newton(problem, w, banded_gn) -> Iterate | None:
    """:func:`evaluate_problem` for a problem without equalities that gives its Gauss-Newton model
    in band storage, ``gauss_newton_band(w) -> (r (p,), 2 Jr^T r (n,), 2 Jr^T Jr (BandedSPD))`` (e.g.
    the phase profile of Eq. 10): the model is the Iterate's ``grams``, no Jacobian is formed.
    None when the problem has equalities (then the usual path)."""
    n = w.shape[0]
    h, Jh = checked_pair(problem.equalities(w), n, "equalities", "dh/dw")
    if h.shape[0]:
        return None
    r, g, H = banded_gn(w)
    if type(H) is not BandedSPD or H.shape != (n, n) or g.shape != (n,):
        raise InputError(f"gauss_newton_band must return (r, g (n,), H BandedSPD (n, n)) for n = {n}")
    rr, hh = _finite_sumsq(r, h, w)
    if not math.isfinite(float(np.dot(g, g))) or not np.isfinite(H.ab).all():
        raise non_finite_error("gauss_newton_band", w, "check the cost features and the start")
    pt = Iterate(w, r, None, h, Jh, rr, hh)
    pt.grams = (g, H, None)
    return pt


def _finite_sumsq(r: np.ndarray, h: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """``(r^T r, h^T h)``; raises a NumericalError naming the culprit when either is NaN or inf."""
    rr = sumsq(r)
    hh = sumsq(h)
    if not math.isfinite(rr):
        raise non_finite_error("residuals", w, "check the cost features (a division by zero or an overflow) and the start")
    if not math.isfinite(hh):
        raise non_finite_error("equalities", w, "check the constraint h(w, theta) and its domain")
    return rr, hh


def sumsq(v: np.ndarray) -> float:
    """``v^T v`` for v: (k,); a Python loop for short vectors (cheaper than a numpy call)."""
    if v.shape[0] <= _SMALL:
        total = 0.0
        for x in v.tolist():
            total += x * x
        return total
    return float(np.dot(v, v))


def dot(a: np.ndarray, b: np.ndarray) -> float:
    """``a^T b`` for a, b: (k,), as :func:`sumsq`."""
    if a.shape[0] <= _SMALL:
        total = 0.0
        for x, y in zip(a.tolist(), b.tolist()):
            total += x * y
        return total
    return float(np.dot(a, b))


def max_abs(h: np.ndarray) -> float:
    """``max |h|`` (0 for an empty h)."""
    q = h.shape[0]
    if q <= _SMALL:
        return max(map(abs, h.tolist())) if q else 0.0
    return float(np.maximum.reduce(np.abs(h)))


def max_diagonal(G) -> float:
    """Largest diagonal entry of a square G: ndarray, scipy.sparse, or for a tiny problem the
    packed 2 x 2 ``(G00, G01, G11)`` or nested list ``[[G00, G01], [G01, G11]]``; 0 when empty."""
    if type(G) is tuple:
        return G[0] if G[0] >= G[2] else G[2]
    if type(G) is list:  # the nested 2 x 2 H that gauss_newton returns for a tiny problem
        return G[0][0] if G[0][0] >= G[1][1] else G[1][1]
    diag = G.diagonal()
    if diag.shape[0] <= _SMALL:
        return max(diag.tolist(), default=0.0)
    return float(np.maximum.reduce(diag))


def compute_grams(pt: Iterate) -> tuple:
    """``(2 Jr^T r, 2 Jr^T Jr, 2 Jh^T Jh)`` at ``pt`` (the last is None without constraints).

    For tiny problems (:func:`_is_tiny`) Python floats: ``(g0, g1)`` and packed symmetric
    ``(G00, G01, G11)``; arrays otherwise.
    """
    Jr, Jh, q = pt.Jr, pt.Jh, pt.h.shape[0]
    if pt.affine is not None:  # r = Jr w - b: constant 2 Jr^T Jr and gradient 2 Jr^T r = 2 Jr^T Jr w - 2 Jr^T b
        H, c = pt.affine
        JhJh = None
        if pt.JhJh is not None:
            JhJh = pt.JhJh
        elif q:
            JhJh = SupportGram.from_jacobian(Jh, 2.0) if type(H) is BandedSPD else 2.0 * (Jh.T @ Jh)
        if pt.AT is not None:  # 2 A^T r: A's few non-zeros instead of the band of H (Eq. 9: kron(S, I))
            gJ = pt.AT @ (2.0 * pt.r)
        else:
            gJ = np.asarray(H @ pt.w, dtype=float).ravel() - c
        grams = (gJ, H, JhJh)
    elif type(Jr) is not np.ndarray:  # scipy.sparse
        grams = (
            np.asarray(Jr.T @ (2.0 * pt.r), dtype=float).ravel(),
            2.0 * (Jr.T @ Jr),
            2.0 * (Jh.T @ Jh) if q else None,
        )
    elif _is_tiny(Jr, Jh):
        g0 = g1 = a00 = a01 = a11 = 0.0
        for (j0, j1), rk in zip(Jr.tolist(), pt.r.tolist()):
            g0 += j0 * rk
            g1 += j1 * rk
            a00 += j0 * j0
            a01 += j0 * j1
            a11 += j1 * j1
        JhJh = None
        if q:
            c00 = c01 = c11 = 0.0
            for j0, j1 in Jh.tolist():
                c00 += j0 * j0
                c01 += j0 * j1
                c11 += j1 * j1
            JhJh = (2.0 * c00, 2.0 * c01, 2.0 * c11)
        grams = ((2.0 * g0, 2.0 * g1), (2.0 * a00, 2.0 * a01, 2.0 * a11), JhJh)
    else:  # np.dot skips the matmul dispatch, which dominates for small n
        JrT = Jr.T
        grams = (np.dot(JrT, 2.0 * pt.r), np.dot(JrT, 2.0 * Jr), np.dot(Jh.T, 2.0 * Jh) if q else None)
    pt.grams = grams
    return grams


def _is_tiny(Jr: np.ndarray, Jh: np.ndarray) -> bool:
    """Dense problems with n = 2 and at most 8 rows (the synthetic benchmark): Gauss-Newton on
    Python floats, since numpy's per-call overhead costs more than the arithmetic there, and the
    2 x 2 trust-region step has a closed form (:func:`corl.trajectory.solver.linalg.model_step`)."""
    return Jr.shape[1] == 2 and Jr.shape[0] + Jh.shape[0] <= 8


def lagrangian(pt: Iterate, lam: np.ndarray, mu: float) -> tuple[float, float]:
    """L_A = r^T r + lam^T h + mu h^T h, and the rounding noise of its evaluation."""
    lin = dot(lam, pt.h)
    return pt.rr + lin + mu * pt.hh, NOISE * (pt.rr + abs(lin) + mu * pt.hh)


def gauss_newton(pt: Iterate, lam: np.ndarray, mu: float) -> tuple[np.ndarray, Jacobian]:
    """Gradient g (n,) and Gauss-Newton Hessian H (n, n) of L_A at ``pt``.

    For tiny dense problems (:func:`_is_tiny`) g is a list and H a nested 2 x 2 list of floats,
    which :func:`corl.trajectory.solver.linalg.model_step` takes as they are.
    """
    # g = 2 Jr^T r + Jh^T (lam + 2 mu h);  H = 2 (Jr^T Jr + mu Jh^T Jh)  (second derivatives of r, h dropped)
    g, H, JhJh = pt.grams or compute_grams(pt)
    if type(H) is tuple:  # tiny dense problem: Python floats, H packed as (H00, H01, H11)
        g0, g1 = g
        if JhJh is not None:
            two_mu = 2.0 * mu
            for lam_k, h_k, (j0, j1) in zip(lam.tolist(), pt.h.tolist(), pt.Jh.tolist()):
                c = lam_k + two_mu * h_k
                g0 += c * j0
                g1 += c * j1
            H = (H[0] + mu * JhJh[0], H[1] + mu * JhJh[1], H[2] + mu * JhJh[2])
        return [g0, g1], [[H[0], H[1]], [H[1], H[2]]]
    if JhJh is not None:
        lam_mu = lam + (2.0 * mu) * pt.h
        if type(JhJh) is SupportGram:  # Jh^T lam_mu touches only the support columns
            g = g.copy()
            g[JhJh.support] += lam_mu @ JhJh.Js
        else:
            g = g + (np.dot(lam_mu, pt.Jh) if type(pt.Jh) is np.ndarray else pt.Jh.T @ lam_mu)
        H = H + mu * JhJh
        if pt.curvature is not None:  # + sum_i (lam + 2 mu h)_i d^2 h_i / dw^2: Newton instead of Gauss-Newton
            C = pt.curvature(pt.w, lam_mu)
            if C is not None:
                if type(C) is SupportGram and type(H) is not BandedSPD:
                    C = C.toarray() if type(H) is np.ndarray else sp.csr_matrix(C.toarray())
                if not (type(C) is SupportGram and C.add_into(H)):  # H is a new matrix: add in place
                    H = H + C
    if type(H) is BandedSPD:
        g = np.asarray(g, dtype=float).ravel()
    elif type(H) is not np.ndarray:  # scipy.sparse
        H = H.tocsc()
        g = np.asarray(g, dtype=float).ravel()
    return g, H


def check_gradient(g: np.ndarray) -> None:
    """Raise a NumericalError naming the Jacobians when the gradient g (n,) is NaN or inf."""
    if not math.isfinite(float(np.dot(g, g))):
        raise NumericalError(
            "the gradient of the augmented Lagrangian is NaN or inf; check the Jacobians dr/dw and dh/dw"
        )
