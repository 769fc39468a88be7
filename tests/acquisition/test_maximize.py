"""The acquisition maximiser in m = 3 and 4: thin boundary bands (boundary seeding), and PIBU's level."""

from __future__ import annotations

import numpy as np
import pytest

from corl.acquisition import PIBU, MaximizerConfig, maximize
from corl.errors import InputError
from corl.optimizers.gpconfig import ClassifierConfig, RegressionConfig
from corl.problem import Bounds

OLD = MaximizerConfig(samples_nd=2048, boundary_pairs=0)  # the maximiser before boundary seeding


class ThinShell:
    """PIBU's shape in m dimensions: a broad PI bump (0.8) near a corner and, on a shell
    ``|x - c| = 0.3`` of thickness ``width``, a boundary term 0.85 + 0.1 (x1 - c1) / 0.3, highest
    at the shell's top. ``boundary_level`` is positive inside the shell, like PIBU's ``p - 0.5``."""

    def __init__(self, m: int, width: float) -> None:
        self.c, self.r0, self.width = np.full(m, 0.5), 0.3, width

    def boundary_level(self, X):
        return self.r0 - np.linalg.norm(X - self.c, axis=1)

    def __call__(self, X):
        bump = 0.8 * np.exp(-((X - 0.1) ** 2).sum(1) / 0.02)
        on_shell = np.abs(self.boundary_level(X)) < self.width / 2
        return np.where(on_shell, 0.85 + 0.1 * (X[:, 1] - self.c[1]) / self.r0, bump)


@pytest.mark.parametrize("m", [3, 4])
def test_a_thin_band_missed_by_random_points_is_found_by_boundary_seeding(m):
    # a shell 1e-4 of the box thick: ~1e-4 of the 3-D box's volume, 5e-5 of the 4-D one's
    acq, box = ThinShell(m, 1e-4), Bounds(np.zeros(m), np.ones(m))
    for seed in range(5):
        x, v = maximize(acq, box, rng=np.random.default_rng(seed))
        assert abs(acq.boundary_level(x[None])[0]) < 5e-5  # on the band
        assert v > 0.9  # and high on it (the top is 0.95; the bump only 0.8)
        _, v_old = maximize(acq, box, rng=np.random.default_rng(seed), config=OLD)
        assert v_old < 0.85  # 2,048 Sobol points step over the band and return the bump


def test_one_and_two_dimensions_ignore_the_level():
    # 1-D and 2-D must stay exactly as they were (the paper's tables): the level is never called
    class Level:
        def __call__(self, X):
            return -((X - 0.3) ** 2).sum(1)

        def boundary_level(self, X):
            raise AssertionError("boundary_level used in m <= 2")

    for m in (1, 2):
        x, _ = maximize(Level(), Bounds(np.zeros(m), np.ones(m)), rng=np.random.default_rng(0))
        np.testing.assert_allclose(x, 0.3, atol=1e-3)


def test_pibu_boundary_level_is_zero_mid_band_and_positive_inside():
    rng = np.random.default_rng(3)
    X = rng.random((30, 3))
    s = np.linalg.norm(X - 0.5, axis=1) < 0.3
    cl = ClassifierConfig(lengthscale=0.2, signal_std=10.0).build().fit(X, s)
    rg = RegressionConfig(lengthscale=0.2, signal_std=10.0, noise_std=0.11).build().fit(X[s], -((X[s] - 0.5) ** 2).sum(1))
    acq = PIBU(rg, cl, 0.0)
    U = rng.random((4000, 3))
    parts, level = acq.parts(U), acq.boundary_level(U)
    np.testing.assert_allclose(level, parts["proba"] - 0.5, atol=1e-12)
    assert np.all(parts["band"] == (np.abs(level) <= 0.05 + 1e-12))
    # on a 3-D PIBU acquisition the seeded maximiser is at least as good as the random one
    box = Bounds(np.zeros(3), np.ones(3))
    for seed in range(3):
        _, v_new = maximize(acq, box, rng=np.random.default_rng(seed), extra=X)
        _, v_old = maximize(acq, box, rng=np.random.default_rng(seed), extra=X, config=OLD)
        assert v_new >= v_old - 0.01


def test_config_validates_the_seeding():
    with pytest.raises(InputError):
        MaximizerConfig(boundary_pairs=-1)
    with pytest.raises(InputError):
        MaximizerConfig(boundary_rounds=0)
