"""SEIB: safe expected improvement with a return-gated boundary term (the ``CORL`` default).

PIBU (Eq. 17) adds the boundary uncertainty of g_S wherever the boundary is uncertain, whatever
the return there, and its PI settles beside the best point. SEIB keeps PIBU's two regions but
changes what each one rewards:

    EI_xi(theta)  = sigma_R(theta) * [u Phi(u) + phi(u)],
                    u = (mu_R(theta) - R^+ - xi) / sigma_R(theta)                    (EI, margin xi)
    UCB_R(theta)  = mu_R(theta) + beta * sigma_R(theta)
    a(theta) = [p(theta) >= p_inner] * EI_xi(theta) / scale                          (inner term)
             + [p_band <= p(theta) < p_inner] * [UCB_R(theta) > R^+ + xi_b]
               * max(EI_xi(theta) / scale, w_b * V(theta))                            (gated boundary)

with ``V = sqrt(V_gS) / sf`` (PIBU's normalised boundary uncertainty, Eq. 17's second term),
``p = E[sigma(g_S)]`` and the gate's margin ``xi_b = max(xi, band_rel * scale)`` (``band_rel`` 0 by
default: ``xi_b = xi``; larger, the edge is mapped only where the gain could be larger, with fewer
failures and fewer optima found: docs/safe_bo_suite.md). Consequences:

* the boundary is explored only where the return model leaves room to beat R^+ by the margin
  (``UCB_R > R^+ + xi_b``): an edge where R is low is never mapped;
* EI with a margin xi (a fraction of the spread of observed returns) is ~0 beside the best
  point, so the method moves on instead of stalling (PI's failure mode) and stops when
  ``max a < stop_value`` -- nothing left that is both plausible and safe;
* points are only proposed where ``p >= p_band``, so every failure lies in the boundary band;
* when the gated ``a`` has nothing left (``max a < stop_value``) while there are fewer than
  ``trust_per_dim * m`` successes, the optimizer tries once more with the gate open
  (``gated=False``): a return model fitted on a few clustered points (e.g. along a level set of
  R) can be wrong about every unexplored edge, and stopping there would strand the search.

Looking beyond the band (``beyond=True``). The gate above asks ``UCB_R`` at the band point, just
beside the data; a return model fitted on points clustered at a local peak is confident there
that R is lower, so the gate closes and the search stops although R may be higher a little
further out (a GP that reverts to its prior mean). When the band-point gate leaves nothing
(``max a < stop_value`` or the maximiser lands on a sampled point), the optimizer asks again with

    gate(theta) = max_k UCB_R(theta + d_k l n(theta)) > R^+_mu + beyond_rel * scale,

    n(theta) = -grad mu_g / |grad mu_g|   (outward normal of the safe set, from g_S's latent mean)
    l        = min(l_R, l_S) per dimension, d_k in ``reach`` (0 .. 1 length scale)
    R^+_mu   = min(R^+, max of mu_R at the data)  (a noise-explaining fit cannot hide behind one
               lucky sample)

where the ray ends at the first point known to fail (within ``ray_open`` g_S length scales of a
failed trial: g_S's negative prior mean makes its ``p`` hardly lower there than in unexplored
space, so the failures themselves are asked) and at the box. The margin ``beyond_rel * scale``
is larger than ``xi``: the step risks a failure in the band, so it must promise a real gain, not a
sliver along an edge already mapped.

Looking far (``far=True``). One length scale is not enough to cross a valley of R wider than
that (a local peak by the start, the optimum a few length scales away through safe but unexplored
space): there g_R still extrapolates the valley. When the look beyond leaves nothing either, the
optimizer asks once more with the ray reaching ``far_reach`` (up to 4) length scales, where g_R
reverts to its prior, with a UCB width of its own, ``far_beta`` (2, as ``beta``; 2.5 crosses more
valleys, whose low returns pull g_R's prior mean and signal std down as they are explored, but it
also walks down slopes that only fall, at a cost in trials and failures: docs/safe_bo_suite.md),
and a smaller margin ``far_rel * scale``, but only from band points that lie
``far_open`` (2) g_S length scales or more from every failed trial, on a ray that stays that far
from them: a look into unexplored space, not along an edge already mapped (where R rising outward
would otherwise pull every far look back into the known boundary). A failure well behind the band
point does not count (cosine with the outward normal below ``-far_behind``, 0.25, in g_S's
length-scale units): a failure at the other end of a narrow safe set says nothing about the side
the ray explores (in 1-D it closed the far look on the open side: bumps-1d stopped at a local
peak after 8 trials). With ``far_lengthscale``
(none by default) the far look sees g_S refitted with that length-scale prior median, a fraction
of the box (the fit's own: 0.1): its band lies further out, so each far step reaches further into
untried space (more optima across valleys, a few more failures: docs/safe_bo_suite.md; the
optimizer fits it, :class:`corl.optimizers.safe.SafeBOOptimizer`). The far look's distances
(``far_open``, the ray's length scales, ``far_behind``'s scaling) are then measured in that g_S's
longer length scales too. Only band points count then:
the inner EI had its turn in the first ask, and its maximum beside the best point would otherwise
stop the search there (the maximiser lands on a sampled point). Looking far, the boundary term
is weighted by the promise, ``w_b * V * (max_k UCB_R - R^+_mu - far_rel * scale) / scale``: the
search heads where R may be highest instead of growing the safe set evenly around its whole
frontier (in 2-D that costs a trial per length scale of frontier, and the valley's returns pull
g_R's prior mean down before the far side is reached).

Glossary
--------
settings  : ``p_band``, ``band_rel``, ``far`` (``far_reach = ()`` when off), ``far_beta`` and
            ``far_lengthscale`` are a user's (:class:`SEIBConfig`); every other name above in lower
            case is this module's named constant in upper case (``p_inner`` is :data:`P_INNER`)
mu, var   : mean and latent variance of g_R at candidates, (s,)
g, g_var  : latent mean and variance of g_S, (s,); ``sf`` its kernel's signal std
p         : predictive success probability ``E[sigma(g_S)]``, (s,)
best      : R^+, the highest observed successful return (Eq. 15)
scale     : spread of the observed returns (std, or |R^+| with fewer than two); EI is divided by it
xi        : improvement margin ``xi_rel * scale``
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr

from corl import checks
from corl.errors import InputError
from corl.gp.classification import expected_sigmoid
from corl.numerics import floor_variance

__all__ = ["SEIBConfig", "SEIBTuning", "SEIB", "expected_improvement"]

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)
_HALF_AND_MARGIN = 0.5 + 1e-6  # p_band above this: p >= p_band needs a positive latent mean, beyond rounding


def expected_improvement(mu, var, threshold: float) -> np.ndarray:
    """``E[max(R - threshold, 0)]`` for ``R ~ N(mu, var)``; ``mu``, ``var``: (s,) -> (s,), >= 0."""
    sd = np.sqrt(floor_variance(np.asarray(var, dtype=float)))
    u = (np.asarray(mu, dtype=float) - threshold) / sd
    return np.maximum(sd * (u * ndtr(u) + _INV_SQRT_2PI * np.exp(-0.5 * u * u)), 0.0)


def _is_number(v) -> bool:
    """A real number (Python or NumPy), not a bool."""
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, (bool, np.bool_))


# SEIB's fixed values, chosen on the safe-BO suite's training problems (docs/safe_bo_suite.md). A
# user moves SEIB along the trade-offs of :class:`SEIBConfig` instead; each reason is beside its value.
P_INNER = 0.7  # inner region p >= 0.7: EI alone acts there; below it lies the band the edge is mapped in (PIBU: 0.55)
XI_REL = 0.01  # EI's margin, 1 % of the returns' spread: EI beside the best point is ~0, so the search moves on
BETA = 2.0  # UCB width of the band-point gate: an edge is mapped where R may beat R^+ two posterior stds out
BOUNDARY_WEIGHT = 0.1  # V's weight on a gated edge: an uncertain edge is mapped when EI is below a tenth of a spread
STOP_VALUE = 1e-4  # stop when max a < 1e-4 spreads: nothing both plausible and safe is left
TRUST_PER_DIM = 5  # below 5 successes per dimension, open the gate once before stopping: a g_R on few points
#                    can be wrong about every edge
BEYOND_REL = 0.5  # looking beyond, R must plausibly beat R^+ by half a spread: a step into the band risks a failure
RAY_OPEN = 1.0  # a ray ends within one g_S length scale of a failed trial: g_S's p hardly drops there
REACH = (0.0, 0.25, 0.5, 0.75, 1.0)  # the look beyond the band: ray points up to one length scale out
FAR_REACH = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)  # the far look: up to 4 length scales, where g_R has reverted
FAR_REL = 0.1  # looking far, a tenth of a spread suffices: the ray starts well clear of every failure
FAR_OPEN = 2.0  # looking far: band point and ray two g_S length scales from failures (untried space, not an edge)
NOISE_GATE = 2.0  # with a return noise declared (a sensor's std), an edge is mapped only where R may beat R^+ by
#                  two of those stds: with noisy readings beside the best, UCB_R stays a noise std or two above R^+
#                  there, and the band beside an optimum on the edge was probed again and again (crescent-2d: 12.6
#                  true failures per run at 5 % noise, 3.7 clean). Not from g_R's fitted noise: on clean problems
#                  with several peaks (bumps-1d, far-edge-3d) g_R often explains the peaks as noise (a fitted noise
#                  of 0.8 of the returns' spread), and the gate then stopped 3-6 of 20 runs short of the optimum
FAR_BEHIND = 0.25  # looking far, a failure behind the band point (cosine below -0.25 to the outward normal)
#                    does not block: it says nothing about the side the ray explores (bumps-1d, 1-D)


@checks.keywords()
@dataclass(frozen=True)
class SEIBTuning:
    """SEIB's fixed values in one place (defaults: the named constants above, with their reasons).

    Not a user setting: :mod:`corl.contexts` refines a start it trusts with values of its own
    (``IN_A_NEW_SCENE``), and tests move one value to check what it does.
    """

    p_inner: float = P_INNER
    xi_rel: float = XI_REL
    beta: float = BETA
    boundary_weight: float = BOUNDARY_WEIGHT
    stop_value: float = STOP_VALUE
    trust_per_dim: int = TRUST_PER_DIM
    beyond_rel: float = BEYOND_REL
    ray_open: float = RAY_OPEN
    reach: tuple[float, ...] = REACH
    far_reach: tuple[float, ...] = FAR_REACH
    far_rel: float = FAR_REL
    far_open: float = FAR_OPEN
    far_behind: float = FAR_BEHIND

    def __post_init__(self) -> None:
        names = ("p_inner", "xi_rel", "beta", "boundary_weight", "stop_value", "trust_per_dim", "beyond_rel",
                 "ray_open", "far_rel", "far_open", "far_behind")
        wrong = [f"{n}={getattr(self, n)!r}" for n in names if not _is_number(getattr(self, n))]
        if wrong:
            raise InputError(f"SEIBTuning values must be numbers, got {', '.join(wrong)}")
        if not 0.0 < self.p_inner < 1.0:
            raise InputError(f"SEIBTuning.p_inner must lie in (0, 1), got {self.p_inner}")
        values = (self.xi_rel, self.beta, self.boundary_weight, self.stop_value, self.trust_per_dim,
                  self.beyond_rel, self.ray_open, self.far_rel, self.far_open)
        if any(np.isnan(v) for v in values) or min(values) < 0:
            raise InputError("xi_rel, beta, boundary_weight, stop_value, trust_per_dim, beyond_rel, ray_open, far_rel "
                             "and far_open must be >= 0 (beyond_rel=inf never looks beyond the band)")
        if not np.isfinite(self.beta):
            raise InputError(f"beta (a UCB width) must be finite, got {self.beta}")
        if not np.isfinite(self.stop_value):  # inf would stop before the first look
            raise InputError(f"stop_value must be a finite number >= 0, got {self.stop_value}")
        if not -1.0 <= self.far_behind <= 1.0:  # NaN fails too
            raise InputError(f"far_behind is a cosine, in [-1, 1] (1: every failure blocks), got {self.far_behind!r}")
        for name, least in (("reach", 1), ("far_reach", 0)):  # kept as tuples of floats: hashable, equal when equal
            object.__setattr__(self, name, _distances(name, getattr(self, name), least))


def _distances(name: str, value, least: int) -> tuple[float, ...]:
    """``value`` as a tuple of at least ``least`` finite distances >= 0 (in length scales), else InputError."""
    ok = isinstance(value, (tuple, list)) and len(value) >= least and all(
        _is_number(d) and np.isfinite(d) and d >= 0 for d in value)
    if not ok:
        raise InputError(f"SEIBTuning.{name} needs a tuple of finite distances >= 0 in length scales"
                         f"{' (at least one)' if least else ''}, got {value!r}")
    return tuple(float(d) for d in value)


_MOVED = "it is now fixed: the named constant corl.acquisition.safe_ei.{} (its reason is beside it)"
_REMOVED = {name: _MOVED.format(name.upper()) for name in
            ("p_inner", "xi_rel", "beta", "boundary_weight", "stop_value", "trust_per_dim", "beyond_rel", "ray_open",
             "reach", "far_rel", "far_open", "far_behind")}
_REMOVED["far_reach"] = ("give far=False to never look far (the far look's reach is the named constant "
                         "corl.acquisition.safe_ei.FAR_REACH)")
_REMOVED["far_ladder"] = ("it found 12 more optima in the suite's 840 runs at 6 % more failures, where "
                          "far_lengthscale=0.15 finds 28 more at 4 % more: use far_lengthscale")


@checks.keywords(removed=_REMOVED)
@dataclass(frozen=True)
class SEIBConfig:
    """The five settings of SEIB a user may move, each along one trade-off (docs/guide/safe-bo.md).

    Every other value is a named constant of this module, with the reason for it beside it.
    """

    p_band: float = 0.55  # the lowest success probability ever proposed: higher fails less, maps edges later
    band_rel: float = 0.0  # an edge is mapped only for a gain of this fraction of the spread: fewer failures, fewer optima
    far: bool = True  # look across valleys of R before stopping: more optima, more trials (False: stop sooner)
    far_beta: float = 2.0  # the far look's UCB width: 2.5 crosses more valleys, walks down more slopes that only fall
    far_lengthscale: float | None = None  # the far look's g_S length-scale prior median (box fraction): 0.15 finds
    #                                       more optima for a few more failures (None: the fit's own, 0.1)
    _tuning: SEIBTuning = field(default=SEIBTuning(), repr=False)  # corl's own: see SEIBTuning

    def __post_init__(self) -> None:
        wrong = [f"{n}={getattr(self, n)!r}" for n in ("p_band", "band_rel", "far_beta")
                 if not _is_number(getattr(self, n))]
        if wrong:
            raise InputError(f"SEIBConfig settings must be numbers, got {', '.join(wrong)}")
        if not isinstance(self.far, (bool, np.bool_)):
            raise InputError(f"SEIBConfig.far must be True or False, got {self.far!r}")
        if not isinstance(self._tuning, SEIBTuning):
            raise InputError(f"SEIBConfig._tuning must be a SEIBTuning, got {type(self._tuning).__name__}")
        if not 0.0 < self.p_band <= self.p_inner < 1.0:
            raise InputError(f"SEIB needs 0 < p_band <= {self.p_inner} (the inner region's p; NaN is refused), "
                             f"got p_band={self.p_band}")
        if np.isnan(self.band_rel) or self.band_rel < 0:
            raise InputError(f"SEIBConfig.band_rel must be >= 0 (inf: never map the edge at the band points), "
                             f"got {self.band_rel}")
        if not (np.isfinite(self.far_beta) and self.far_beta >= 0):
            raise InputError(f"SEIBConfig.far_beta (a UCB width) must be finite and >= 0, got {self.far_beta}")
        fl = self.far_lengthscale
        if fl is not None and not (_is_number(fl) and np.isfinite(fl) and fl > 0):
            raise InputError(f"far_lengthscale is g_S's length-scale prior median for the far look, a fraction of the "
                             f"box > 0 (None: the same g_S), got {fl!r}")

    def __repr__(self) -> str:  # the tuning shows only when it is not the default (corl.contexts' refining one)
        shown = ", ".join(f"{n}={getattr(self, n)!r}" for n in ("p_band", "band_rel", "far", "far_beta", "far_lengthscale"))
        return f"SEIBConfig({shown}{'' if self._tuning == SEIBTuning() else f', _tuning={self._tuning!r}'})"

    # the fixed values, read where SEIB needs them
    p_inner = property(lambda self: self._tuning.p_inner)
    xi_rel = property(lambda self: self._tuning.xi_rel)
    beta = property(lambda self: self._tuning.beta)
    boundary_weight = property(lambda self: self._tuning.boundary_weight)
    stop_value = property(lambda self: self._tuning.stop_value)
    trust_per_dim = property(lambda self: self._tuning.trust_per_dim)
    beyond_rel = property(lambda self: self._tuning.beyond_rel)
    ray_open = property(lambda self: self._tuning.ray_open)
    reach = property(lambda self: self._tuning.reach)
    far_rel = property(lambda self: self._tuning.far_rel)
    far_open = property(lambda self: self._tuning.far_open)
    far_behind = property(lambda self: self._tuning.far_behind)

    @property
    def far_reach(self) -> tuple[float, ...]:
        """The far look's ray, in length scales; () when ``far`` is off."""
        return self._tuning.far_reach if self.far else ()

    def check_classifier(self, classifier) -> None:
        """Refuse ``far_lengthscale`` where it cannot act: ``classifier`` (a ``ClassifierConfig``) must be
        fitted, with the median inside its length-scale prior's bounds. Called where settings are made."""
        fl = self.far_lengthscale
        if fl is None:
            return
        if not getattr(classifier, "fit_hyperparameters", False):
            raise InputError("SEIBConfig.far_lengthscale is a prior median of g_S's fit, but g_S's hyperparameters are "
                             "fixed here: give fitted ones (e.g. OptimizerSettings.for_box(box, fitted=True), or "
                             "corl.methods.USER_SETTINGS in a task's method_settings()) or leave far_lengthscale None")
        prior = classifier.priors.lengthscale
        if not prior.low <= fl <= prior.high:
            raise InputError(f"SEIBConfig.far_lengthscale must lie within g_S's length-scale prior bounds "
                             f"[{prior.low}, {prior.high}] (fractions of the box), got {fl}")


class SEIB:
    """SEIB evaluated on fitted models.

    Parameters
    ----------
    regression : fitted g_R on successful points, or None (then only the boundary term acts and
        it is not gated: with no return seen there is nothing to compare against).
    classifier : fitted g_S on every point.
    best_return : R^+.
    scale : spread of the returns (> 0).
    config : :class:`SEIBConfig`.
    gated : gate the boundary term by ``UCB_R > R^+ + xi_b``; ``False`` gives the ungated boundary
        term (PIBU's, weighted by ``w_b``), which the optimizer falls back to when the gated
        acquisition has nothing left: the return model may be wrong about an unexplored edge.
    beyond : gate a band point by the return just beyond it instead (:meth:`reach_ucb`):
        ``max_k UCB_R(theta_k) > R^+_mu + beyond_rel * scale`` over the ray points ``theta_k``
        that are not known to fail; the optimizer asks this when the band-point gate would stop.
    far : with ``beyond``, look far instead: rays of ``far_reach`` length scales, margin
        ``far_rel``, and only band points and ray points ``far_open`` g_S length scales or more
        from every failed trial; the boundary term is weighted by the gain the ray promises.
    box : ``(lower, upper)`` of the search box, (m,) each; ray points outside it do not count.
    noise_std : a declared std of a return reading, in the returns' units (0: none declared): every gate
        then asks R to beat R^+ by :data:`NOISE_GATE` of it.
    """

    def __init__(self, regression, classifier, best_return: float, scale: float,
                 config: SEIBConfig = SEIBConfig(), *, gated: bool = True, beyond: bool = False,
                 far: bool = False, box=None, noise_std: float = 0.0) -> None:
        if not (np.isfinite(scale) and scale > 0):
            raise InputError(f"scale must be positive and finite, got {scale}")
        self.regression, self.classifier = regression, classifier
        self.best_return, self.scale, self.config = float(best_return), float(scale), config
        self.gated, self.beyond, self.far = bool(gated), bool(beyond), bool(far)
        self.box = None if box is None else (np.asarray(box[0], dtype=float), np.asarray(box[1], dtype=float))
        # the gates' margin for a declared return noise (NOISE_GATE of its stds; 0 when none is declared)
        self.noise_gate = NOISE_GATE * float(noise_std) if np.isfinite(noise_std) and noise_std > 0 else 0.0
        self.incumbent = self.best_return  # the gate's R^+: the best posterior mean at the data, <= R^+
        if regression is not None and len(getattr(regression, "X_", ())):
            self.incumbent = min(self.best_return, float(np.max(regression.predict(regression.X_)[0])))

    def parts(self, X: np.ndarray, latent=None) -> dict[str, np.ndarray]:
        """Every term at candidates ``X`` (s, m): value, ei, ucb_gate, boundary, inner, band, proba.

        ``latent``: g_S's ``(mean, var)`` at ``X`` if already computed.
        """
        cfg = self.config
        g, g_var = self.classifier.predict_latent(X) if latent is None else latent
        p = expected_sigmoid(g, g_var)
        inner = p >= cfg.p_inner
        band = (p >= cfg.p_band) & ~inner
        boundary = np.sqrt(g_var) / float(self.classifier.kernel.signal_std)  # Eq. 17's V, in [0, 1]
        xi = cfg.xi_rel * self.scale
        if self.regression is None:
            ei, gate = np.zeros(len(X)), np.ones(len(X), dtype=bool)
        else:
            # g_R only where a point can be proposed (p >= p_band): elsewhere ei = 0 and the gate is
            # shut, and the value is 0 whatever they are (the maximiser's grid is mostly there)
            need = np.flatnonzero(inner | band)
            ei, gate = np.zeros(len(X)), np.zeros(len(X), dtype=bool)
            mu, var = self.regression.predict(X[need])
            ei[need] = expected_improvement(mu, var, self.best_return + xi) / self.scale  # EI with margin xi
            gate[need] = True
            if self.gated and self.beyond:  # UCB_R on the ray beyond the band point
                rel = cfg.far_rel if self.far else cfg.beyond_rel
                excess = self.reach_ucb(X, band) - (self.incumbent + max(rel * self.scale, self.noise_gate))
                gate = band & (excess > 0)
                if self.far:  # toward the largest promise, not around the whole frontier
                    boundary = boundary * np.where(gate, excess, 0.0) / self.scale
            elif self.gated:  # UCB_R at the band point
                gate[need] = mu + cfg.beta * np.sqrt(var) > self.best_return + max(xi, cfg.band_rel * self.scale,
                                                                                    self.noise_gate)
        edge = np.where(band & gate, np.maximum(ei, cfg.boundary_weight * boundary), 0.0)
        far = self.gated and self.beyond and self.far  # looking far asks the band only: the inner EI
        value = edge if far else np.where(inner, ei, 0.0) + edge  # had its turn and left nothing new
        return {"value": value, "ei": ei, "ucb_gate": gate, "boundary": boundary, "inner": inner,
                "band": band, "proba": p}

    def boundary_level(self, X: np.ndarray) -> np.ndarray:
        """``p - (p_band + p_inner) / 2`` at ``X`` (s, m) -> (s,): zero in the middle of the band.

        The maximiser (:func:`corl.acquisition.maximize.maximize`) seeds candidates where this
        crosses zero; CORL lets it from 5 dimensions on (``BAND_SEEDS_FROM_DIM`` in
        :mod:`corl.optimizers.safe`), where the band is too thin a shell for random points to hit.
        """
        g, g_var = self.classifier.predict_latent(X)
        return expected_sigmoid(g, g_var) - 0.5 * (self.config.p_band + self.config.p_inner)

    def outward(self, X: np.ndarray) -> np.ndarray:
        """Unit outward normals of the safe set at ``X`` (s, m) -> (s, m): ``-grad mu_g / |grad mu_g|``.

        Central differences of g_S's latent mean with a step of 1e-3 of its length scales; where
        the gradient vanishes the normal is 0 (only the point itself is then looked at).
        """
        X = np.asarray(X, dtype=float)
        s, m = X.shape
        h = 1e-3 * np.broadcast_to(np.asarray(self.classifier.kernel.lengthscales, dtype=float), (m,))
        shifted = np.concatenate([X + h[j] * np.eye(m)[j] for j in range(m)]
                                 + [X - h[j] * np.eye(m)[j] for j in range(m)])
        g = self.classifier.predict_latent(shifted)[0].reshape(2, m, s)
        grad = ((g[0] - g[1]) / (2.0 * h[:, None])).T  # (s, m)
        norm = np.linalg.norm(grad, axis=1, keepdims=True)
        return np.where(norm > 0, -grad / np.where(norm > 0, norm, 1.0), 0.0)

    def reach_ucb(self, X: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
        """``max_k UCB_R(theta + d_k l n)`` over ``d_k`` in ``reach``: (s, m) -> (s,); -inf off ``where``.

        ``n`` is the outward normal (:meth:`outward`) and ``d_k l`` a distance of ``d_k`` length
        scales along it, ``l = min(l_R, l_S)`` per dimension (``|step / l| = d_k``, ARD). The ray
        ends at its first point within ``ray_open`` g_S length scales of a failed trial and at the
        box; the band point itself (``d = 0``) always counts. Looking far (``far``): ``far_reach``,
        ``far_open`` and ``far_beta`` instead, the band point counts only if it is that far from
        failures, and failures behind it (cosine to ``n`` below ``-far_behind``, measured in g_S
        length scales) do not count.
        """
        X = np.asarray(X, dtype=float)
        out = np.full(len(X), -np.inf)
        idx = np.flatnonzero(np.ones(len(X), dtype=bool) if where is None else where)
        if idx.size == 0:
            return out
        Xb = X[idx]
        n = self.outward(Xb)
        m = X.shape[1]
        ls = np.minimum(np.broadcast_to(np.asarray(self.regression.kernel.lengthscales, dtype=float), (m,)),
                        np.broadcast_to(np.asarray(self.classifier.kernel.lengthscales, dtype=float), (m,)))
        unit = np.linalg.norm(n / ls, axis=1, keepdims=True)
        step = np.where(unit > 0, n / np.where(unit > 0, unit, 1.0), 0.0)  # one length scale along n
        reach = self.config.far_reach if self.far else self.config.reach
        radius = self.config.far_open if self.far else self.config.ray_open
        pts = np.concatenate([Xb + d * step for d in reach])
        mu, var = self.regression.predict(pts)
        beta = self.config.far_beta if self.far else self.config.beta
        ucb = (mu + beta * np.sqrt(floor_variance(var))).reshape(len(reach), -1)
        open_ = np.ones(ucb.shape, dtype=bool)
        failed = self.classifier.X_[self.classifier.y_ < 0]
        if len(failed):  # known to fail: within ray_open g_S length scales of a failed trial
            ls_s = np.broadcast_to(np.asarray(self.classifier.kernel.lengthscales, dtype=float), (m,))
            d2 = np.sum(((pts[:, None, :] - failed[None]) / ls_s) ** 2, axis=2)  # (len(reach) * s, f)
            if self.far:  # a failure well behind the band point (on the far side of the safe set) does not block
                u = (failed[None] - Xb[:, None, :]) / ls_s  # (s, f, m), in g_S length scales
                nu = n / ls_s  # the ray's direction in the same scaled space
                cos = np.einsum("sfm,sm->sf", u, nu) / np.maximum(
                    np.linalg.norm(u, axis=2) * np.linalg.norm(nu, axis=1)[:, None], 1e-300)
                behind = (cos < -self.config.far_behind) & (np.linalg.norm(nu, axis=1)[:, None] > 0)
                d2 = np.where(np.tile(behind, (len(reach), 1)), np.inf, d2)
            open_ = (np.min(d2, axis=1) >= radius ** 2).reshape(ucb.shape)
        if self.box is not None:
            lo, hi = self.box
            open_ &= np.all((pts >= lo) & (pts <= hi), axis=1).reshape(ucb.shape)
        if not self.far:
            open_[0] = True  # the band point itself (looking far, it too must be clear of failures)
        open_ = np.cumprod(open_, axis=0).astype(bool)  # the ray ends where failure is known
        out[idx] = np.where(open_, ucb, -np.inf).max(axis=0)
        return out

    def on_lattice(self, X: np.ndarray, axes) -> np.ndarray:
        """Values at the lattice points ``X`` (prod n_j, m) spanned by ``axes`` ('ij' order).

        As :meth:`__call__`, with g_S's mean on the whole lattice from the factorised kernel
        (:meth:`GPClassifier.latent_mean_on_lattice`); the posterior is worked out only at points
        whose mean is positive, so the values are the same.
        """
        lattice = getattr(self.classifier, "latent_mean_on_lattice", None)
        if self.config.p_band < _HALF_AND_MARGIN or lattice is None:
            return self(X)
        value = np.zeros(len(X))
        maybe = np.flatnonzero(lattice(axes) > 0.0)
        if maybe.size:
            value[maybe] = self(X[maybe])
        return value

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Acquisition values at candidates ``X`` (s, m) -> (s,).

        The value at a point depends on that point alone, and it is 0 wherever ``p < p_band``. With
        ``p_band > 1/2`` that holds wherever g_S's latent mean is <= 0 (then ``E[sigma(g)] <= 1/2``),
        so the full posterior is computed only where the mean is positive: the same values, for a
        fraction of the cost on a maximiser's grid that is mostly unexplored.
        """
        X = np.asarray(X, dtype=float)
        positive = getattr(self.classifier, "predict_latent_positive", None)
        if self.config.p_band < _HALF_AND_MARGIN or positive is None or len(X) == 0:
            return self.parts(X)["value"]
        value = np.zeros(len(X))
        g, g_var = positive(X)
        maybe = np.flatnonzero(g > 0.0)
        if maybe.size:
            value[maybe] = self.parts(X[maybe], latent=(g[maybe], g_var[maybe]))["value"]
        return value
