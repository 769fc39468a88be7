"""Maximising an acquisition over a box.

The acquisitions here are cheap to evaluate in batches but not smooth (PIBU has indicator
functions), so the maximiser is derivative-free and vectorised: a dense grid (m <= 2) or a
scrambled Sobol set (m >= 3), then ``refine_rounds`` rounds of zooming: dense local grids or
samples around the best ``n_keep`` candidates in boxes that shrink by ``shrink`` each round.

In 1-D the default resolution is ``width / 2048`` before refinement and about ``1e-6 * width``
after it; in 2-D ``width / 128`` and about ``1e-4 * width``: below the stopping distance used by
PIBU (1e-3) for boxes up to a few units wide. In m >= 3 dimensions the result is a good local
maximum near the best Sobol candidates, not a certified global one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.stats import qmc

from corl.errors import InputError
from corl.problem import Bounds

__all__ = ["MaximizerConfig", "maximize"]


@dataclass(frozen=True)
class MaximizerConfig:
    grid_1d: int = 2049
    grid_2d: int = 129
    samples_nd: int = 2048
    n_keep: int = 4
    refine_1d: int = 33
    refine_2d: int = 9
    refine_nd: int = 64
    refine_rounds: int = 3
    shrink: float = 0.1

    def __post_init__(self) -> None:
        sizes = (self.grid_1d, self.grid_2d, self.samples_nd, self.n_keep, self.refine_1d, self.refine_2d,
                 self.refine_nd)
        if min(sizes) < 2:
            raise InputError("maximizer sizes must be at least 2")
        if not 0.0 < self.shrink < 1.0 or self.refine_rounds < 0:
            raise InputError("shrink must lie in (0, 1) and refine_rounds be >= 0")


def _initial_candidates(m: int, cfg: MaximizerConfig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Unit-box candidates (s, m) and the spacing (m,) of the structure they come from."""
    if m == 1:
        u = np.linspace(0.0, 1.0, cfg.grid_1d)[:, None]
        return u, np.array([1.0 / (cfg.grid_1d - 1)])
    if m == 2:
        g = np.linspace(0.0, 1.0, cfg.grid_2d)
        u = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
        return u, np.full(2, 1.0 / (cfg.grid_2d - 1))
    sobol = qmc.Sobol(d=m, scramble=True, seed=rng)
    u = sobol.random(cfg.samples_nd)
    return u, np.full(m, cfg.samples_nd ** (-1.0 / m))


def _local_candidates(center: np.ndarray, half: np.ndarray, cfg: MaximizerConfig, rng: np.random.Generator) -> np.ndarray:
    m = center.shape[0]
    if m <= 2:
        k = cfg.refine_1d if m == 1 else cfg.refine_2d
        axes = [np.linspace(c - h, c + h, k) for c, h in zip(center, half)]
        pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)
    else:
        pts = center + (rng.random((cfg.refine_nd * m, m)) * 2.0 - 1.0) * half
    return np.clip(pts, 0.0, 1.0)


def maximize(
    acquisition: Callable[[np.ndarray], np.ndarray],
    bounds: Bounds,
    *,
    rng: np.random.Generator,
    config: MaximizerConfig = MaximizerConfig(),
    extra: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Return ``(theta (m,), value)`` maximising ``acquisition`` (callable on (s, m) -> (s,)).

    ``extra`` (k, m) are additional candidates (e.g. the sampled points), always evaluated.
    Ties are broken towards the first candidate, so the result is deterministic given ``rng``.
    """
    m = bounds.dim
    U, spacing = _initial_candidates(m, config, rng)
    if extra is not None and len(extra):
        U = np.vstack([U, bounds.to_unit(np.asarray(extra, dtype=float).reshape(-1, m))])
    values = np.asarray(acquisition(bounds.from_unit(U)), dtype=float)
    values = np.where(np.isfinite(values), values, -np.inf)
    half = spacing.copy()
    for _ in range(config.refine_rounds):
        keep = np.argsort(-values, kind="stable")[: config.n_keep]
        local = np.vstack([_local_candidates(U[k], half, config, rng) for k in keep])
        local_values = np.asarray(acquisition(bounds.from_unit(local)), dtype=float)
        local_values = np.where(np.isfinite(local_values), local_values, -np.inf)
        U = np.vstack([U[keep], local])
        values = np.concatenate([values[keep], local_values])
        half = half * config.shrink * 2.0
    best = int(np.argmax(values))
    return bounds.from_unit(U[best]), float(values[best])
