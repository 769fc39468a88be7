"""Sequential quadratic programming for Eq. 8 on banded trajectory problems.

For a B-spline trajectory the cost of Eq. 7 is linear in w (``r = A w - b``, constant banded
``H_J = 2 A^T A``) and the equalities are few (start, goal, a contact point: Eq. 6). The augmented
Lagrangian of :mod:`corl.trajectory.solver` then needs more iterations the more knots there are:
the smooth modes of ``A^T A`` have eigenvalues that shrink with the knot spacing, and its
Levenberg-Marquardt damping and penalty updates crawl along them. Newton steps on the KKT
conditions of Eq. 8 do not (Nocedal & Wright, Numerical Optimization, Eq. 18.9 and Alg. 18.3)::

    (H_J + sum_i lam_i d2h_i + 2 mu Jh^T Jh) d + Jh^T lam+ = -(gJ + 2 mu Jh^T h),    Jh d = -h,

solved through the Schur complement on one banded Cholesky factor, inside the trust region
(:mod:`corl.trajectory.solver.kkt`). The ``mu`` terms cancel on ``Jh d = -h``, so they do not change the
step, but they make the matrix definite where ``H_J`` is only semi-definite (the start and goal
constraints pin the motions that cost no acceleration). When the constraint curvature makes the
matrix indefinite, mu is raised, and failing that the step is the Gauss-Newton one without it
(or, with the ball active, More & Sorensen's shift makes up for it).

Globalization: a backtracking line search on ``(w, lam)`` with the augmented-Lagrangian merit
function ``phi = J + lam^T h + rho h^T h / 2`` (N&W Sec. 18.5, as in SNOPT), with ``rho`` raised
so that the step is a descent direction, ``phi'(0) <= -d^T H d / 2``. It accepts full steps near a
solution (no Maratos effect), so the convergence is quadratic there; every trial point lies on the
segment from the current point to the trust-region step, hence inside the ball.

When no KKT step exists at some iterate (``dh/dw`` rank-deficient, the linearized constraints out
of reach of the ball, a singular Hessian) or the line search fails away from ``h = 0``, :func:`sqp`
gives up and :func:`corl.trajectory.solver.solve` continues with the augmented Lagrangian from
that point.

Glossary
--------
w, n       : decision variables (n,)
J, H_J, gJ : cost ``r^T r``, its constant banded Hessian ``2 A^T A`` and its gradient (n,)
h, Jh      : equality constraints (q,) and their Jacobian, kept on its support (``Js``: (q, s))
lam        : multiplier estimate (q,); lam+ the one from the KKT step, dlam = lam+ - lam
mu         : weight of ``2 Jh^T Jh`` in the KKT Hessian (no effect on the step)
rho        : penalty of the merit function phi
nu         : multiplier of the trust-region ball (a shift of the KKT Hessian)
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg.blas import dsbmv

from corl.errors import NumericalError
from corl.trajectory.solver.banded import BandedSPD, BandedSum, SupportGram
from corl.trajectory.solver.kkt import IndefiniteHessian, StepFailure, constrained_step, structure_of
from corl.trajectory.solver.model import NOISE, Iterate, compute_grams, max_diagonal, sumsq
from corl.trajectory.solver.problem import SolverConfig, SolverMethod
from corl.trajectory.solver.state import SolveState

__all__ = ["sqp_applies", "sqp", "KKTModel"]

_ARMIJO = 1e-4  # sufficient decrease of the merit function, relative to alpha phi'(0)
_MAX_BACKTRACKS = 12  # halvings of the step before the line search gives up
_NOISE_MARGIN = 100.0  # a failed line search at a feasible point is convergence if |phi'(0)| <= this x rounding
_MU_RELATIVE = 1.0  # first mu: 2 mu Jh^T Jh on the scale of H_J (maxdiag ratio); the step does not depend on it
_MU_GROWTH = 100.0  # raise of mu when H is indefinite with the constraint curvature
_MU_MAX = 1e6  # mu stays below this multiple of its first value
_EPS = float(np.finfo(float).eps)


def sqp_applies(pt: Iterate, config: SolverConfig) -> bool:
    """True when ``config`` asks for SQP and the problem has a banded affine cost and equalities."""
    return (
        config.method is SolverMethod.SQP
        and pt.h.shape[0] > 0
        and pt.affine is not None
        and type(pt.affine[0]) is BandedSPD
    )


class KKTModel:
    """The KKT model at one iterate: ``H`` (a :class:`~corl.trajectory.solver.banded.BandedSum`, the
    banded ``H_J`` plus the constraint blocks), ``g``, ``gJ`` and the constraint Jacobian's support.

    ``curvature_block`` is the dense block of ``sum_i lam_i d2h_i`` on its columns (or None);
    :meth:`nu_definite` derives from it, when a ball step asks, a shift that makes ``H`` definite.
    """

    __slots__ = ("H", "g", "gJ", "support", "Js", "curvature_block", "structure")

    def __init__(self, pt: Iterate, lam: np.ndarray, mu: float, curvature: bool, ball: bool) -> None:
        H_J, _ = pt.affine
        gJ, _, gram = pt.grams or compute_grams(pt)  # gJ = H_J w - c; gram = 2 Jh^T Jh with Js = Jh[:, support]
        self.support, self.Js, self.gJ = gram.support, gram.Js, gJ
        self.structure = structure_of(gram)  # which rows fix a parameter (cached per problem)
        G = mu * gram.G  # H = H_J + 2 mu Jh^T Jh (+ curvature), added into the band when factorized
        extra = ()
        self.curvature_block = None
        if curvature and pt.curvature is not None and np.any(lam):  # + sum_i lam_i d2h_i (Newton)
            C = pt.curvature(pt.w, lam)
            if C is not None:
                if type(C) is not SupportGram:
                    raise StepFailure("the constraint curvature is no SupportGram; it cannot join the banded Hessian")
                at = gram.covers(C)
                if at is not None and at.shape[0] and int(at[-1] - at[0]) + 1 == at.shape[0]:  # one window of them
                    G[at[0] : at[-1] + 1, at[0] : at[-1] + 1] += C.G
                elif at is not None:  # on the constraint columns: one block
                    G[at[:, None], at] += C.G
                else:
                    extra = (C,)
                self.curvature_block = C.G if ball and C.G.shape[0] else None  # only a ball step uses it
        block = SupportGram(gram.support, G, gram.n, gram.pairs, gram.Js, gram.pattern)
        self.H = BandedSum(H_J, (block,) + extra)
        self.g = gJ.copy()
        self.g[self.support] += (2.0 * mu) * np.dot(pt.h, self.Js)  # + 2 mu Jh^T h

    def nu_definite(self) -> float:
        """A shift that makes ``H + nu I`` definite: ``H_J + 2 mu Jh^T Jh`` is semi-definite, so minus
        the lowest eigenvalue of the curvature block (0 when it has none below 0). One ``eigvalsh``
        of the block, computed only when the ball step needs it (H indefinite at the first shifts)."""
        if self.curvature_block is None:
            return 0.0
        lowest = float(np.linalg.eigvalsh(self.curvature_block)[0])
        return -lowest * (1.0 + 1e-6) + 1e-12 * max_diagonal(self.H) if lowest < 0.0 else 0.0


def _step(pt: Iterate, lam: np.ndarray, mu: float, mu_max: float, u, radius: float, nu_guess: float, newton: bool):
    """The KKT step at ``pt`` with the Newton Hessian (``newton``) - with mu raised (up to
    ``mu_max``) when ``mu Jh^T Jh`` is too weak to make it definite - or, when it stays indefinite
    and no ball makes up for it, the Gauss-Newton one without the constraint curvature.

    Returns ``(model, d, lam+, z, nu, mu)``; raises StepFailure.
    """
    tries = [(True, weight) for weight in (mu, mu * _MU_GROWTH, mu * _MU_GROWTH**2) if weight <= mu_max and newton]
    for curvature, weight in tries + [(False, mu)]:
        model = KKTModel(pt, lam, weight, curvature, u is not None)
        try:
            d, lam_plus, z, nu = constrained_step(
                model.H, model.g, model.support, model.Js, pt.h, u, radius,
                nu_definite=model.nu_definite, nu_guess=nu_guess, structure=model.structure,
            )
            return model, d, lam_plus, z, nu, weight
        except IndefiniteHessian:
            continue
    raise StepFailure("the Hessian is singular or indefinite even without the constraint curvature")


def sqp(state: SolveState, pt: Iterate) -> tuple[Iterate, np.ndarray | None, bool, str]:
    """SQP iterations from ``pt`` (N&W Alg. 18.3 with the merit function and ball of the module docstring).

    ``state`` is the solve's :class:`~corl.trajectory.solver.state.SolveState` (config, ball,
    counters, history), shared with the augmented Lagrangian that takes over when SQP gives up.

    Returns
    -------
    (pt, lam, converged, status) : the final point, multipliers ``lam`` (q,) with
        ``grad J + Jh^T lam (+ nu (w - center)) = 0``, and the outcome in words; or
        ``(pt, None, False, reason)`` when SQP gave up at ``pt`` (the caller falls back on the
        augmented Lagrangian).
    """
    cfg = state.config
    _, H_J, gram = pt.grams or compute_grams(pt)
    c_cost, c_con = max_diagonal(H_J), max_diagonal(gram)
    mu = mu0 = _MU_RELATIVE * (c_cost / c_con if c_cost > 0 and c_con > 0 else 1.0)
    rounding = _Rounding(pt)
    lam, rho, nu = np.zeros(pt.h.shape[0]), 0.0, 0.0
    while True:
        if state.iterations >= cfg.max_iterations:
            return pt, lam, False, _budget_status(cfg, pt)
        u = None if state.center is None else pt.w - state.center
        try:
            model, d, lam_plus, z, nu, mu = _step(pt, lam, mu, _MU_MAX * mu0, u, state.radius, nu, True)
            curvature = _curvature(model, d, lam_plus, pt.h, u, nu)
            if not curvature > 0.0:  # negative curvature along a ball step: no descent guarantee, take Gauss-Newton
                model, d, lam_plus, z, nu, _ = _step(pt, lam, mu, _MU_MAX * mu0, u, state.radius, nu, False)
                curvature = _curvature(model, d, lam_plus, pt.h, u, nu)
        except StepFailure as err:
            return pt, None, False, str(err)
        dn = math.sqrt(sumsq(d))
        if not math.isfinite(dn):
            raise NumericalError("the SQP step is NaN or inf; the Jacobians are probably non-finite or wildly scaled")
        feasible = pt.err <= cfg.tol_constraint
        # Stop at a feasible point when the step is small, or when it is rounding noise: a step
        # d = (H + nu I)^{-1} e driven by an error e of gJ has d^T (H + nu I) d = -e^T d <= ||e|| ||d||.
        small = dn <= cfg.tol_step * (1.0 + math.sqrt(sumsq(pt.w)))
        if feasible and (small or curvature + 0.5 * nu * dn * dn <= rounding.gradient(pt.w) * dn):
            how = "the step is below tol_step" if small else "the step is at the rounding level of the gradient"
            return pt, lam_plus, True, _converged_status(cfg, pt, how)
        # Merit phi(alpha) = J + lam(alpha)^T h + rho h^T h / 2 along (d, dlam); phi'(0) uses Jh d = -h.
        # On the ball's boundary phi'(0) <= -d^T (H + nu I / 2) d + ... (-nu u^T d <= nu ||d||^2 / 2), so
        # rho is raised until phi'(0) <= -curvature / 2 with curvature = d^T (H + nu I / 2) d.
        dlam = lam_plus - lam
        lin = float(np.dot(lam, pt.h))
        slope = float(np.dot(model.gJ, d)) - lin + float(np.dot(pt.h, dlam))
        if pt.hh > 0.0:
            rho = max(rho, 2.0 * (slope + 0.5 * curvature) / pt.hh)
        slope -= rho * pt.hh
        noise = _MeritNoise(NOISE * (pt.rr + abs(lin) + 0.5 * rho * pt.hh), rounding, pt)  # of phi, when asked
        if feasible and -slope <= noise():
            how = "the predicted decrease of the merit function is below its rounding error"
            return pt, lam_plus, True, _converged_status(cfg, pt, how)
        found = _line_search(state, pt, lam, dlam, d, z, slope, rho, noise) if slope < 0.0 else None
        if found is None:
            if state.iterations >= cfg.max_iterations:
                return pt, lam, False, _budget_status(cfg, pt)
            if feasible and -slope <= _NOISE_MARGIN * noise():
                return pt, lam_plus, True, _converged_status(cfg, pt, "the merit function is flat to rounding")
            return pt, None, False, (
                f"the line search on the merit function failed ({_MAX_BACKTRACKS} halvings of the step, "
                f"phi'(0) = {slope:.3g})"
            )
        trial, alpha = found
        state.record(trial, alpha * dn, nu, rho)
        pt, lam = trial, lam + alpha * dlam


def _curvature(model: KKTModel, d: np.ndarray, lam_plus: np.ndarray, h: np.ndarray, u, nu: float) -> float:
    """``d^T (H + nu I / 2) d``: positive when the step is a descent direction of the merit function.

    From the KKT equations of the step, ``(H + nu I) d + Jh^T lam+ = -(g + nu u)`` and ``Jh d = -h``:
    ``d^T H d = -(g + nu u)^T d + h^T lam+ - nu d^T d`` (dot products instead of a product with H;
    the KKT residual is at the rounding level of ``|g| |d|``, far below ``d^T H d`` until d itself is)."""
    dd = float(np.dot(d, d))
    gd = float(np.dot(model.g, d)) + (nu * float(np.dot(u, d)) if nu else 0.0)
    return -gd + float(np.dot(h, lam_plus)) - 0.5 * nu * dd


def _line_search(state: SolveState, pt: Iterate, lam, dlam, d, z, slope: float, rho: float, noise: _MeritNoise):
    """Backtracking from ``alpha = 1`` until ``phi`` decreases by ``_ARMIJO alpha phi'(0)``
    (``slope``), or - when that is below its rounding error ``noise()`` - does not rise beyond it.

    Returns ``(trial point, alpha)``, or None when the halvings or the iteration budget ran out.
    """
    phi = pt.rr + float(np.dot(lam, pt.h)) + 0.5 * rho * pt.hh
    alpha = 1.0
    for _ in range(_MAX_BACKTRACKS):
        if state.iterations >= state.config.max_iterations:
            return None
        state.iterations += 1
        trial = state.evaluate(state.new_point(pt.w, d, z) if alpha == 1.0 else pt.w + alpha * d)
        lam_t = lam + alpha * dlam
        phi_t = trial.rr + float(np.dot(lam_t, trial.h)) + 0.5 * rho * trial.hh
        if phi_t <= phi + _ARMIJO * alpha * slope or (-alpha * slope <= noise() and phi_t <= phi + noise()):
            return trial, alpha
        alpha *= 0.5
    return None


class _MeritNoise:
    """The rounding error of the merit function at ``pt``: ``base`` plus that of ``J`` (a product
    with ``|A|``), computed on the first call only - most iterations never ask for it."""

    __slots__ = ("base", "rounding", "pt", "value")

    def __init__(self, base: float, rounding: _Rounding, pt: Iterate) -> None:
        self.base, self.rounding, self.pt, self.value = base, rounding, pt, None

    def __call__(self) -> float:
        if self.value is None:
            self.value = self.base + self.rounding.cost(self.pt)
        return self.value


class _Rounding:
    """Rounding errors of what the SQP compares, for a cost ``r = A w - b`` with ``H_J = 2 A^T A``.

    With ``A`` and ``H_J`` scaled like 1/dt^2 and 1/dt^4, ``r`` and ``gJ = H_J w - c`` are small
    differences of large terms, so their rounding errors are ``eps (|A| |w| + |b|)`` and
    ``eps (|H_J| |w| + |c|)`` entry by entry, far above ``eps |r|`` and ``eps |gJ|``.
    """

    def __init__(self, pt: Iterate) -> None:
        self.pt0 = pt  # |H_J|, |c| and |A| are taken from it on first use
        self.abs_ab = self.abs_c = self.abs_A = None

    def gradient(self, w: np.ndarray) -> float:
        """Norm of the rounding error of ``gJ`` at w."""
        if self.abs_ab is None:
            H_J, c = self.pt0.affine
            self.abs_ab, self.abs_c = np.asfortranarray(np.abs(H_J.ab)), np.abs(c)
        terms = dsbmv(self.abs_ab.shape[0] - 1, 1.0, self.abs_ab, np.abs(w)) + self.abs_c
        return _EPS * math.sqrt(sumsq(terms))

    def cost(self, pt: Iterate) -> float:
        """Rounding error of ``J = r^T r`` at pt: ``2 |r|^T dr`` with ``dr = eps (2 |A| |w| + |r|)``
        (``|b| <= |A| |w| + |r|``)."""
        if self.abs_A is None:
            Jr = self.pt0.Jr
            self.abs_A = abs(Jr) if type(Jr) is not np.ndarray else np.abs(Jr)
        abs_r = np.abs(pt.r)
        dr = 2.0 * np.asarray(self.abs_A @ np.abs(pt.w)).ravel() + abs_r
        return 2.0 * _EPS * float(np.dot(abs_r, dr))


def _converged_status(cfg: SolverConfig, pt: Iterate, how: str) -> str:
    return f"converged (SQP): {how} and max|h| = {pt.err:.2e} <= tol_constraint = {cfg.tol_constraint:g}"


def _budget_status(cfg: SolverConfig, pt: Iterate) -> str:
    return (
        f"not converged: max_iterations = {cfg.max_iterations} SQP iterations used, "
        f"max|h| = {pt.err:.2e}; raise max_iterations or loosen tol_step / tol_constraint"
    )
