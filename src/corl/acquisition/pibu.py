"""PIBU: probability of improvement with boundary uncertainty (Eq. 17).

    a_PIBU(theta) = PI_gR(theta) [g_S(theta) >= 0] + V_gS(theta) [g_S(theta) = 0]      (Eq. 17)

Eq. 17 leaves open which variance is meant on the boundary, how the boundary is located and when
to stop. Two readings are implemented:

``PIBUVariant.AUTHORS`` (default) follows the authors' published MATLAB release:
  * inner region: predictive class probability ``p(s=1 | theta) > inner_threshold`` (0.55);
  * boundary: the band ``band_low <= p <= band_high`` (0.45..0.55);
  * boundary term: latent std of g_S divided by its signal std (so in [0, 1] like PI), set to
    zero where it is below ``boundary_threshold`` (0.55);
  * stop when the maximiser lies within 1e-3 of a sampled point (the optimizer's stopping rule,
    ``corl.optimizers.bo.BOConfig.stop_distance``; the acquisition itself does not stop).
``PIBUVariant.LITERAL`` reads Eq. 17 word for word:
  * inner region: latent mean ``g_S >= 0``;
  * boundary: where the latent mean crosses zero (``|g_S| <= zero_tolerance``);
  * boundary term: the raw latent variance ``V_gS``;
  * stop on a small step ``||theta_{d+1} - theta_d|| < eps_theta`` (the optimizer's rule).

Glossary
--------
p          : predictive probability of success, (s,)
g, g_var   : latent mean and variance of the classifier GP g_S, (s,)
sf         : signal std of g_S's kernel
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import numpy as np

from corl.acquisition.pi import probability_of_improvement
from corl.errors import InputError
from corl.gp.classification import expected_sigmoid

__all__ = ["PIBUVariant", "PIBUConfig", "PIBU"]


class PIBUVariant(str, enum.Enum):
    AUTHORS = "authors"
    LITERAL = "literal"


@dataclass(frozen=True)
class PIBUConfig:
    """Settings of Eq. 17; the defaults are the authors' published values."""

    variant: PIBUVariant = PIBUVariant.AUTHORS
    inner_threshold: float = 0.55
    band_low: float = 0.45
    band_high: float = 0.55
    boundary_threshold: float = 0.55
    zero_tolerance: float = 0.25

    def __post_init__(self) -> None:
        object.__setattr__(self, "variant", PIBUVariant(self.variant))
        if not 0.0 < self.band_low <= self.band_high < 1.0:
            raise InputError(f"PIBU band needs 0 < band_low <= band_high < 1, got {self.band_low}, {self.band_high}")
        if not 0.0 < self.inner_threshold < 1.0:
            raise InputError(f"inner_threshold must lie in (0, 1), got {self.inner_threshold}")
        if self.boundary_threshold < 0 or self.zero_tolerance <= 0:
            raise InputError("boundary_threshold must be >= 0 and zero_tolerance > 0")


class PIBU:
    """Eq. 17 evaluated on fitted models.

    Parameters
    ----------
    regression : fitted return GP g_R (on successful points only), or None when there is none
        yet (then PI is 0 everywhere).
    classifier : fitted success classifier g_S.
    best_return : R(theta^+) (Eq. 15).
    config : :class:`PIBUConfig`.
    """

    def __init__(self, regression, classifier, best_return: float, config: PIBUConfig = PIBUConfig()) -> None:
        self.regression = regression
        self.classifier = classifier
        self.best_return = best_return
        self.config = config

    def parts(self, X: np.ndarray) -> dict[str, np.ndarray]:
        """Every term of Eq. 17 at candidates ``X`` (s, m): pi, boundary, inner, band, proba, latent."""
        cfg = self.config
        g, g_var = self.classifier.predict_latent(X)
        if self.regression is not None:
            mu, var = self.regression.predict(X)
            pi = probability_of_improvement(mu, var, self.best_return)
        else:
            pi = np.zeros(len(X))
        if cfg.variant is PIBUVariant.AUTHORS:
            proba = expected_sigmoid(g, g_var)  # E[sigma(g)] from the latent already computed
            inner = proba > cfg.inner_threshold
            band = (proba >= cfg.band_low) & (proba <= cfg.band_high)
            sf = float(self.classifier.kernel.signal_std)
            boundary = np.sqrt(g_var) / sf
            boundary = np.where(boundary >= cfg.boundary_threshold, boundary, 0.0)
        else:
            proba = None
            inner = g >= 0.0
            band = np.abs(g) <= cfg.zero_tolerance
            boundary = g_var
        value = np.where(inner, pi, 0.0) + np.where(band, boundary, 0.0)
        return {"value": value, "pi": pi, "boundary": boundary, "inner": inner, "band": band,
                "proba": proba, "latent_mean": g, "latent_var": g_var}

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Acquisition values at candidates ``X`` (s, m) -> (s,)."""
        return self.parts(X)["value"]

    def boundary_level(self, X: np.ndarray) -> np.ndarray:
        """Where the boundary band lies, for the maximiser: (s, m) -> (s,), zero mid-band, > 0 inside.

        ``p - (band_low + band_high) / 2`` (authors) or the latent mean ``g`` (literal).
        """
        g, g_var = self.classifier.predict_latent(X)
        cfg = self.config
        if cfg.variant is PIBUVariant.AUTHORS:
            return expected_sigmoid(g, g_var) - 0.5 * (cfg.band_low + cfg.band_high)
        return g
