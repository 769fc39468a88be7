"""Maximising an acquisition over a box.

The acquisitions here are cheap to evaluate in batches but not smooth (PIBU has indicator
functions), so the maximiser is derivative-free and vectorised: a dense grid (m <= 2) or a
scrambled Sobol set (m >= 3), then ``refine_rounds`` rounds of zooming: dense local grids or
samples around the best ``n_keep`` candidates in boxes that shrink by ``shrink`` each round.

In 1-D the default resolution is ``width / 2048`` before refinement and about ``1e-6 * width``
after it; in 2-D ``width / 128`` and about ``1e-4 * width``: below the stopping distance used by
PIBU (1e-3) for boxes up to a few units wide.

In m >= 3 dimensions no grid is affordable, and PIBU's boundary term lives on a band a few
thousandths of the box thick (p in 0.45..0.55) around the estimated safe set: a fraction 1e-3 of
a 4-D box or less, which 2,048 random points often miss. Two things find it there:

* more Sobol points (``samples_nd``, 4,096);
* *boundary seeding*: an acquisition that knows where its thin band is says so with a method
  ``boundary_level(X) -> (s,)``, a continuous function that is positive on the inner side, negative
  outside and zero inside the band (PIBU: ``p - 0.5``). The level is read at the first
  ``level_samples`` Sobol points and the sampled points; the ``boundary_pairs`` of them closest
  to the zero level are each paired with their nearest point on the other side, and each
  segment is cut at the level crossing by ``boundary_rounds`` rounds of quartering (4^-6 of the
  segment). Those crossing points join the candidates before the zoom. The band is then found
  whenever one of those points lies on each side of it, whatever its thickness.

1-D and 2-D are unchanged by either (the paper's tables come from them). In m >= 3 the result is a
good local maximum near the best candidates, not a certified global one.

Glossary
--------
U      : candidates in the unit box ``[0, 1]^m``, (s, m); ``bounds.from_unit(U)`` are in theta
level  : ``acquisition.boundary_level`` at candidates, (s,); > 0 inside, < 0 outside the band
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
    samples_nd: int = 4096
    n_keep: int = 4
    refine_1d: int = 33
    refine_2d: int = 9
    refine_nd: int = 64
    refine_rounds: int = 3
    shrink: float = 0.1
    boundary_pairs: int = 128  # m >= 3: segments cut at the acquisition's boundary level (0: off)
    boundary_rounds: int = 6  # quartering rounds per segment: the crossing to 4^-6 of its length
    level_samples: int = 1024  # the level is read at this many of the Sobol points (and the data)

    def __post_init__(self) -> None:
        sizes = (self.grid_1d, self.grid_2d, self.samples_nd, self.n_keep, self.refine_1d, self.refine_2d,
                 self.refine_nd)
        if min(sizes) < 2:
            raise InputError("maximizer sizes must be at least 2")
        if self.boundary_pairs < 0 or self.boundary_rounds < 1 or self.level_samples < 2:
            raise InputError("boundary_pairs must be >= 0, boundary_rounds >= 1 and level_samples >= 2")
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


_QUARTERS = np.array([0.25, 0.5, 0.75])
_CUTS = np.array([0.0, 0.25, 0.5, 0.75, 1.0])


def _boundary_seeds(level: Callable[[np.ndarray], np.ndarray], U: np.ndarray, bounds: Bounds,
                    cfg: MaximizerConfig) -> np.ndarray:
    """Points (k, m) of the unit box where ``level`` crosses zero, between candidates ``U`` (s, m).

    The ``boundary_pairs`` candidates with the smallest ``|level|`` are paired with their nearest
    candidate of the opposite sign; each segment (inner end ``a``, outer end ``b``) is quartered
    ``boundary_rounds`` times, keeping the quarter where the level first turns non-positive.
    """
    from scipy.spatial import cKDTree

    lev = np.asarray(level(bounds.from_unit(U)), dtype=float)
    inside, outside = np.isfinite(lev) & (lev > 0), np.isfinite(lev) & (lev <= 0)
    if not inside.any() or not outside.any():
        return np.empty((0, U.shape[1]))
    near = np.argsort(np.where(np.isfinite(lev), np.abs(lev), np.inf), kind="stable")[: cfg.boundary_pairs]
    near = near[np.isfinite(lev[near])]
    seeds_in = near[inside[near]]
    seeds_out = near[outside[near]]
    U_in, U_out = U[inside], U[outside]
    a_parts, b_parts = [U[seeds_in]], [U[seeds_out]]
    if len(seeds_in):  # inner seed -> nearest outer candidate
        b_parts.insert(0, U_out[cKDTree(U_out).query(U[seeds_in])[1]])
    if len(seeds_out):  # outer seed -> nearest inner candidate
        a_parts.append(U_in[cKDTree(U_in).query(U[seeds_out])[1]])
    a, b = np.vstack(a_parts), np.vstack(b_parts)  # rows pair up: a inner, b outer
    k, m = a.shape
    for _ in range(cfg.boundary_rounds):
        d = b - a
        P = a[:, None, :] + _QUARTERS[None, :, None] * d[:, None, :]  # (k, 3, m)
        lv = np.asarray(level(bounds.from_unit(P.reshape(-1, m))), dtype=float).reshape(k, 3)
        outer = ~(lv > 0)  # NaN counts as outside
        j = np.where(outer.any(axis=1), np.argmax(outer, axis=1), 3)  # the quarter [cut j, cut j + 1]
        a, b = a + _CUTS[j][:, None] * d, a + _CUTS[j + 1][:, None] * d
    return np.clip(0.5 * (a + b), 0.0, 1.0)


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
    In m >= 3, an ``acquisition.boundary_level`` method seeds candidates on its thin band (module
    docstring). Ties are broken towards the first candidate, so the result is deterministic given ``rng``.
    """
    m = bounds.dim
    U, spacing = _initial_candidates(m, config, rng)
    sobol = U[: config.level_samples]
    if extra is not None and len(extra):
        E = bounds.to_unit(np.asarray(extra, dtype=float).reshape(-1, m))
        U, sobol = np.vstack([U, E]), np.vstack([sobol, E])
    level = getattr(acquisition, "boundary_level", None)
    if m >= 3 and config.boundary_pairs > 0 and callable(level):
        U = np.vstack([U, _boundary_seeds(level, sobol, bounds, config)])
    on_lattice = getattr(acquisition, "on_lattice", None)
    if m == 2 and callable(on_lattice):  # the lattice first, at a fraction of the cost (same values)
        n = config.grid_2d
        X = bounds.from_unit(U)
        lattice = X[: n * n]
        axes = [lattice.reshape(n, n, 2)[:, 0, 0], lattice.reshape(n, n, 2)[0, :, 1]]
        values = np.concatenate([np.asarray(on_lattice(lattice, axes), dtype=float),
                                 np.asarray(acquisition(X[n * n:]), dtype=float)])  # the extra points
    else:
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
