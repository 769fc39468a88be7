"""An acquisition restricted to the points a second model allows (:class:`Guarded`).

A safe method's acquisition is -inf where its own g_S forbids a point; :class:`Guarded` adds a second
test, e.g. the scene's own g_S in a contextual run (:class:`corl.contexts.guard.SceneGuard`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["Guarded"]


class Guarded:
    """An acquisition that is -inf where ``allowed`` is False; everything else is the acquisition's."""

    def __init__(self, acquisition, allowed) -> None:
        self.acquisition, self.allowed = acquisition, allowed

    def __call__(self, X) -> np.ndarray:
        return np.where(self.allowed(X), self.acquisition(X), -np.inf)

    def on_lattice(self, lattice, axes) -> np.ndarray:
        own = getattr(self.acquisition, "on_lattice", None)
        values = own(lattice, axes) if callable(own) else self.acquisition(lattice)
        return np.where(self.allowed(lattice), values, -np.inf)

    def __getattr__(self, name):  # boundary_level, the models, ... of the acquisition
        if name.startswith("__") or name in ("acquisition", "allowed"):
            raise AttributeError(name)
        return getattr(self.acquisition, name)
