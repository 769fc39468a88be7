"""The scene's own data govern where a skill's joint models are unsure: :class:`SceneGuard`.

In a new scene, the black-box step proposes with SEIB on GPs over ``(theta, c)`` fitted on every
scene's trials (:mod:`corl.contexts.models`). Their length scale over the context says how far one
scene's data reach into another's, fitted from scenes whose safe sets may move in ways the new one
does not follow. On a family where they did, the joint g_S called thetas safe that failed in the new
scene, and a skill failed more there than learning from scratch.

A proposal in a scene must therefore also be one the scene's own g_S allows: the classifier that
learning in that scene alone would fit (the task's own classifier settings, on this scene's trials
only: its start and what was tried since) gives it a success probability of at least ``p_min``, the
lower edge of the band in which learning alone would propose (``SEIBConfig.p_band``). The joint
models choose among what both allow. The scene's own g_S extends only as far from its successes as
a length scale, so the region grows trial by trial as it would when learning there alone, and a
failure that the joint models did not expect closes the region around it at once.
"""

from __future__ import annotations

import numpy as np

from corl.optimizers.gpconfig import ModelFitter

__all__ = ["SceneGuard"]


class SceneGuard:
    """The scene's own g_S, as learning there alone would fit it; a proposal needs ``p >= p_min`` there.

    Parameters
    ----------
    theta_bounds : theta's box; ``regression``/``classifier`` : the task's one-scene model configurations.
    p_min : the least success probability of a proposal under the scene's own g_S.
    earlier : ``(theta (d, m), success (d,))`` of this scene's trials before this black-box step
        (an earlier start that failed here), added to the optimizer's own.
    """

    def __init__(self, theta_bounds, regression, classifier, p_min: float, earlier=None) -> None:
        self.fitter = ModelFitter(regression, classifier, theta_bounds)
        self.p_min = float(p_min)
        m = theta_bounds.dim
        theta, success = earlier if earlier is not None else (np.empty((0, m)), np.empty(0, dtype=bool))
        self._earlier = (np.asarray(theta, dtype=float).reshape(-1, m), np.asarray(success, dtype=bool).reshape(-1))
        self._fitted: tuple[int, object] | None = None

    def model(self, X, s):
        """The scene's own g_S on its earlier trials and ``X`` (d, m), ``s`` (d,), fitted once per data size."""
        X = np.vstack([self._earlier[0], np.asarray(X, dtype=float).reshape(-1, self._earlier[0].shape[1])])
        s = np.concatenate([self._earlier[1], np.asarray(s, dtype=bool).reshape(-1)])
        if self._fitted is None or self._fitted[0] != len(X):
            self._fitted = (len(X), self.fitter.classifier(X, s))
        return self._fitted[1]

    def allowed(self, X, s):
        """``(k, m) -> (k,) bool``: the points the scene's own g_S gives ``p >= p_min``."""
        model = self.model(X, s)
        return lambda points: model.predict_proba(np.asarray(points, dtype=float)) >= self.p_min
