"""Safe BO on problems nobody tuned for: corl's CORL and PIBU beside BoTorch and SafeOpt.

Each problem is a box, a start known to succeed, a binary success S(theta) and a return R(theta)
seen only on success. Every method gets nothing but the box and the start (told as trial 1) and
at most ``--budget`` (40) black-box trials in all. Printed per method and problem:

  found    : runs whose best success is within 2 % of the return range of the optimum (the best R
             in the start's connected safe component, on a dense grid)
  fail     : failures per run (mean)
  beyond   : largest distance of a failure from the safe set, in unit-box units (max over runs)
  trials   : trials per run (mean), start included
  ms/it    : mean wall time of one tell + ask (fit both models, maximise)

A real robot is noisy. ``--noise F`` adds Gaussian noise of std F times the return range to every
reported return, ``--flip Q`` reports each trial's success label wrong with probability Q (a failure
reported as a success reports the return formula's value there, noised; a success reported as a
failure reports no return). The start is reported like any trial. The draws come from a generator
seeded by (``--seed``, problem, start), one normal and one uniform per trial in order, so every
method meets the same noise at its k-th trial. Every run is also scored against the TRUE R and S,
and with --noise or --flip the rows show it:

  within5       : runs whose reported best (``opt.best``; BoTorch's and SafeOpt's best reported
                  success) is truly safe with a TRUE return within 5 % of the range of the optimum
  true fail/run : truly unsafe trials per run (mean), whatever was reported
  unsafe best   : runs whose reported best is truly unsafe
  errors        : runs in which the method raised (the one-line message is in the --json record)

With noise or flips, ``found`` asks whether a truly safe trial's TRUE return came within 2 %, and
``beyond`` measures the truly unsafe trials; ``fail`` stays the failures reported. Without either
(the default, or 0), every column is taken from the reported data as it always was.

``set`` says what each problem was to the design of CORL (SEIB): ``training`` problems were used to
design it; ``seen`` ones were held out for one change, run once after it, and looked at while
designing a later one (the look beyond the band, the look far); ``held-out`` ones were written
before a change, run once after it, and no change was kept because of them (docs/safe_bo_suite.md).
Peers are optional (``pip install 'corl-skills[bench]'``): BoTorch's constrained LogEI with the success
labels as a GP constraint (both GPs' hyperparameters fitted), and SafeOpt, which needs GPy and so
numpy < 2: it runs in its own interpreter, ``--safeopt-python`` (a venv with safeopt), and is
skipped when there is none. ``--speed`` times one iteration at 100 points in 2-D for CORL and
BoTorch in this run (the median of ``--speed-repeats``); ``--speed 5x200`` at 200 points of a
run in 5-D, ``--speed-threads 1,2`` at one and two threads, ``--speed-only`` without the suite.
``--jobs N`` runs the (problem, method) pairs in N processes: the same numbers, rows printed as they
finish, the table in order.

    OPENBLAS_NUM_THREADS=1 python benchmarks/safe_bo_suite.py --starts 20
    OPENBLAS_NUM_THREADS=1 python benchmarks/safe_bo_suite.py --starts 20 --noise 0.05 --flip 0.05 --jobs 2
    OPENBLAS_NUM_THREADS=1 python benchmarks/safe_bo_suite.py --speed-only --speed 2x100:uniform 2x100 5x200 \
        --speed-threads 1,2
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import itertools
import json
import os
import subprocess
import sys
import time
import zlib
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))

from corl.errors import CorlError  # noqa: E402
from corl.optimizers.base import StopReason  # noqa: E402
from corl.optimizers.bo import BOConfig, PIBUOptimizer, StopRule  # noqa: E402
from corl.optimizers.gpconfig import FITTED_CLASSIFIER, FITTED_REGRESSION, ClassifierConfig, RegressionConfig  # noqa: E402
from corl.optimizers.safe import SafeBOOptimizer  # noqa: E402
from corl.problem import Bounds, Outcome  # noqa: E402

CORL_METHODS = ("CORL", "PIBU", "PIBU(l=w/10)", "CORL(budget)", "PIBU(budget)", "CORL(declared)")  # corl's own, run at --starts
PEERS = ("PIBU", "PIBU(l=w/10)", "BoTorch", "SafeOpt")  # what CORL is compared with


# ---------------------------------------------------------------------------------------------
# Problems: S and R vectorised over (s, m) arrays in theta units
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Problem:
    name: str
    lower: tuple
    upper: tuple
    start: tuple
    safe: Callable[[np.ndarray], np.ndarray]
    ret: Callable[[np.ndarray], np.ndarray]
    what: str
    role: str = "training"  # training | seen (held out once, then looked at while designing) | held-out
    known: tuple[float, float] | None = None  # (best, worst) return in the start's safe set, worked out by hand:
    # for sets a dense grid cannot resolve (thin ones in 2-3 D) or afford (5-7 D); ``beyond`` is then not measured

    @property
    def bounds(self) -> Bounds:
        return Bounds(np.array(self.lower, float), np.array(self.upper, float))


def _ball(c, r):
    c = np.asarray(c, float)
    return lambda X: np.linalg.norm(X - c, axis=1) < r


def _strip(a, b, half):
    """Points within ``half`` of the segment a-b (2-D)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = b - a

    def inside(X):
        t = np.clip((X - a) @ d / (d @ d), 0.0, 1.0)
        return np.linalg.norm(X - (a + t[:, None] * d), axis=1) < half

    return inside


def _sq(c, w=1.0):
    c = np.asarray(c, float)
    return lambda X: -w * np.sum((X - c) ** 2, axis=1)


def _annulus_sector(X):  # non-convex: a thick ring, cut open on the left
    r = np.linalg.norm(X, axis=1)
    return (r > 1.0) & (r < 2.0) & (X[:, 0] > -0.8)


def _two_discs(X):
    return _ball((-1.5, 0.0), 0.9)(X) | _ball((1.6, 0.5), 1.0)(X)


def _crescent(X):  # disc minus a shifted disc
    return _ball((0.0, 0.0), 2.0)(X) & ~_ball((0.9, 0.0), 1.6)(X)


def _bumps_1d(X):
    x = X[:, 0]
    return np.sin(1.3 * x) + 0.6 * np.exp(-((x - 5.3) ** 2) / 0.3)


def _valley_1d(X):  # a local peak beside the start, the global one across a valley
    x = X[:, 0]
    return 0.7 * np.exp(-((x - 2.8) ** 2) / 0.5) + np.exp(-((x - 7.5) ** 2) / 0.8)


def _neck(X):  # two safe lobes joined by a thin neck
    return (_ball((-1.2, 0.0), 0.8)(X) | _ball((1.2, 0.0), 0.8)(X)
            | ((np.abs(X[:, 1]) < 0.15) & (np.abs(X[:, 0]) < 1.2)))


def _terrace_2d():  # a local peak by the start, the optimum across a wide valley
    def ret(X):
        return (0.6 * np.exp(-np.sum((X - np.array([-1.6, 0.0])) ** 2, axis=1) / 0.4)
                + np.exp(-np.sum((X - np.array([1.7, 0.4])) ** 2, axis=1) / 0.6))
    return ret


def _dip_1d(X):  # a local peak by the start, the optimum at the far edge
    x = X[:, 0]
    return 0.5 * np.exp(-((x - 2.0) ** 2) / 0.3) + 0.12 * x


def _two_peaks(local, top, width: float):  # 0.6 at ``local``, 1 at ``top``: Gaussian bumps of variance width/2
    local, top = np.asarray(local, float), np.asarray(top, float)

    def ret(X):
        return (0.6 * np.exp(-np.sum((X - local) ** 2, axis=1) / width)
                + np.exp(-np.sum((X - top) ** 2, axis=1) / width))
    return ret


def _far_edge_3d(X):  # a local bump near the start, the optimum on the far edge
    bump = 0.8 * np.exp(-np.sum((X - np.array([-1.2, 0.2, 0.0])) ** 2, axis=1) / 0.15)
    return X[:, 0] - 0.3 * (X[:, 1] ** 2 + X[:, 2] ** 2) + bump


def _notched_disc(X):  # a disc with a slot cut in from its right side
    return _ball((0.0, 0.0), 1.6)(X) & ~((X[:, 0] > 0.2) & (np.abs(X[:, 1]) < 0.35))


def _plane_and_bump(X):  # a tilted plane and a bump above the notch
    return 0.4 * X[:, 0] + 0.2 * X[:, 1] + 0.8 * np.exp(-np.sum((X - np.array([0.9, 0.9])) ** 2, axis=1) / 0.3)


PROBLEMS = [
    Problem("edge-1d", (0.0,), (10.0,), (3.0,), lambda X: (X[:, 0] > 2.0) & (X[:, 0] < 6.5),
            lambda X: X[:, 0] - 0.05 * X[:, 0] ** 2, "1-D, optimum on the edge of the safe interval"),
    Problem("inside-2d", (-2.0, -2.0), (2.0, 2.0), (-0.6, -0.7), _ball((0.0, 0.0), 1.2), _sq((0.45, 0.35)),
            "2-D convex disc, optimum well inside"),
    Problem("ring-edge-2d", (-2.5, -2.5), (2.5, 2.5), (1.5, -0.3), _annulus_sector,
            lambda X: X[:, 1] - 0.1 * X[:, 0] ** 2, "2-D non-convex ring sector, optimum on its edge"),
    Problem("two-discs-2d", (-3.0, -2.0), (3.0, 2.5), (1.2, 0.2), _two_discs,
            lambda X: -np.sum((X - np.array([2.3, 1.0])) ** 2, axis=1),
            "2-D two safe discs, start in one; optimum on its far edge"),
    Problem("ellipsoid-3d", (-1.0, -1.0, -1.0), (1.0, 1.0, 1.0), (0.0, 0.0, 0.0),
            lambda X: np.sum((X / np.array([0.8, 0.5, 0.6])) ** 2, axis=1) < 1.0,
            lambda X: X[:, 0] + 0.5 * X[:, 1] - X[:, 2] ** 2, "3-D ellipsoid, optimum on the edge"),
    Problem("inside-4d", (-1.0,) * 4, (1.0,) * 4, (-0.3, -0.3, -0.3, -0.3), _ball((0.0,) * 4, 0.8),
            _sq((0.2, 0.1, 0.2, -0.1)), "4-D ball, optimum inside"),
    # seen: held out for the first SEIB design (bumps-1d, crescent-2d, slab-3d, halfball-4d), run once after it;
    # bumps-1d was then used to design the look beyond the band, and all of them to design the look far
    Problem("bumps-1d", (0.0,), (8.0,), (1.1,), lambda X: (X[:, 0] > 0.5) & (X[:, 0] < 6.0), _bumps_1d,
            "1-D multimodal R, optimum inside next to a local one", role="seen"),
    Problem("crescent-2d", (-2.5, -2.5), (2.5, 2.5), (-1.5, 0.0), _crescent,
            lambda X: -np.sum((X - np.array([0.5, 1.7])) ** 2, axis=1),
            "2-D crescent (non-convex), optimum at its horn's edge", role="seen"),
    Problem("slab-3d", (0.0, 0.0, 0.0), (4.0, 2.0, 1.0), (0.5, 0.5, 0.5),
            lambda X: (X[:, 0] + X[:, 1] < 3.0) & (np.abs(X[:, 2] - 0.5) < 0.35),
            _sq((1.5, 0.8, 0.6)), "3-D slab, optimum inside", role="seen"),
    Problem("halfball-4d", (-1.0,) * 4, (1.0,) * 4, (0.0, 0.0, 0.0, -0.3),
            lambda X: (np.linalg.norm(X, axis=1) < 0.9) & (X[:, 0] + X[:, 1] < 0.5),
            lambda X: X[:, 0] + X[:, 1] - 0.5 * X[:, 2] ** 2 - 0.3 * X[:, 3] ** 2,
            "4-D half ball, optimum on the flat edge", role="seen"),
    # seen: held out for the look beyond the band (written before it, run once after it), then used to design the look far
    Problem("valley-1d", (0.0,), (10.0,), (2.5,), lambda X: (X[:, 0] > 1.0) & (X[:, 0] < 9.0), _valley_1d,
            "1-D local peak beside the start, the optimum across a valley", role="seen"),
    Problem("neck-2d", (-2.5, -1.5), (2.5, 1.5), (-1.3, 0.1), _neck,
            lambda X: -np.sum((X - np.array([1.5, 0.3])) ** 2, axis=1),
            "2-D two safe lobes joined by a thin neck, optimum in the far lobe", role="seen"),
    Problem("far-edge-3d", (-2.0, -1.0, -1.0), (2.0, 1.0, 1.0), (-1.2, 0.0, 0.0),
            lambda X: np.sum((X / np.array([1.8, 0.6, 0.6])) ** 2, axis=1) < 1.0, _far_edge_3d,
            "3-D elongated ellipsoid, local bump by the start, optimum on the far edge", role="seen"),
    # held-out: written before the look far, run once after it (terrace-2d was then used to design the
    # far look's weighting by the promised gain: seen; the other three did not move with it)
    Problem("terrace-2d", (-3.0, -2.0), (3.0, 2.0), (-1.8, 0.2),
            lambda X: np.sum((X / np.array([2.6, 1.6])) ** 2, axis=1) < 1.0, _terrace_2d(),
            "2-D ellipse, a local peak by the start, the optimum across a wide valley", role="seen"),
    Problem("strip-2d", (0.0, 0.0), (4.0, 4.0), (0.8, 0.9), lambda X: np.abs(X[:, 0] - X[:, 1]) < 0.5,
            _sq((3.2, 3.0)), "2-D diagonal strip, optimum inside at its far end", role="held-out"),
    Problem("corner-3d", (-1.0,) * 3, (1.0,) * 3, (-0.2, -0.2, -0.2),
            lambda X: (np.sum(X, axis=1) < 1.2) & (np.linalg.norm(X, axis=1) < 1.1),
            lambda X: np.sum(X, axis=1) - 0.5 * (X[:, 0] - X[:, 1]) ** 2,
            "3-D ball cut by a plane, optimum on the cut", role="held-out"),
    Problem("dip-1d", (0.0,), (10.0,), (2.2,), lambda X: (X[:, 0] > 1.0) & (X[:, 0] < 8.5), _dip_1d,
            "1-D local peak by the start, the optimum at the far edge across a dip", role="held-out"),
    # held-out (batch 4): written before the far look's weighting by the promised gain, run once after it;
    # basin-2d, valley-3d and ridge-2d then seen: used to try a wider far look (far_beta), not kept
    Problem("basin-2d", (-2.5, -2.5), (2.5, 2.5), (-1.1, -0.9), _ball((0.0, 0.0), 2.0),
            _two_peaks((-1.2, -0.8), (1.3, 0.9), 0.5), "2-D disc, a local peak by the start, the optimum "
            "across a valley", role="seen"),
    Problem("valley-3d", (-1.0,) * 3, (1.0,) * 3, (-0.45, 0.05, 0.0), _ball((0.0,) * 3, 0.9),
            _two_peaks((-0.5, 0.0, 0.0), (0.5, 0.2, -0.1), 0.06), "3-D ball, a local peak by the start, the "
            "optimum across a valley", role="seen"),
    Problem("ridge-2d", (-2.5, -1.5), (2.5, 1.5), (-1.4, 0.1),
            lambda X: (np.abs(X[:, 0]) < 2.2) & (np.abs(X[:, 1]) < 1.0),
            lambda X: 0.5 * np.exp(-((X[:, 0] + 1.5) ** 2 + X[:, 1] ** 2) / 0.3) + 0.15 * X[:, 0] - 0.1 * X[:, 1] ** 2,
            "2-D rectangle, a local peak by the start, the optimum on the far edge", role="seen"),
    # held-out (batch 5): written before a wider UCB for the far look was tried (and dropped), run once;
    # wave-2d then seen: used to try it again (far_beta), not kept
    Problem("lobes-3d", (-2.0, -1.0, -1.0), (2.0, 1.0, 1.0), (-1.0, 0.1, 0.0),
            lambda X: (_ball((-1.0, 0.0, 0.0), 0.8)(X) | _ball((1.0, 0.0, 0.0), 0.8)(X)
                       | (np.linalg.norm(X[:, 1:], axis=1) < 0.35) & (np.abs(X[:, 0]) < 1.0)),
            _sq((1.2, 0.3, -0.2)), "3-D two balls joined by a tube, optimum in the far ball", role="held-out"),
    Problem("bowl-1d", (-5.0,), (5.0,), (-3.0,), lambda X: np.abs(X[:, 0]) < 4.0, _sq((2.0,), 0.2),
            "1-D smooth bowl, optimum inside, far from the start", role="held-out"),
    Problem("wave-2d", (-2.0, -2.0), (2.0, 2.0), (-0.5, -0.4), _ball((0.0, 0.0), 1.7),
            lambda X: np.sin(2.0 * X[:, 0]) * np.cos(1.5 * X[:, 1]) + 0.3 * X[:, 1],
            "2-D disc, a wavy R with several peaks", role="seen"),
    # held-out (batch 6): written before the look beyond the band stopped counting the inner EI, run once after it;
    # saddle-2d and knee-1d then seen: used to try far_beta and a doubting length scale, not kept
    Problem("saddle-2d", (-2.0, -2.0), (2.0, 2.0), (-1.1, -0.4), _ball((0.0, 0.0), 1.8),
            _two_peaks((-1.0, -0.5), (0.9, 0.9), 0.3), "2-D disc, a local peak by the start, the optimum "
            "across a valley on the diagonal", role="seen"),
    Problem("cup-3d", (-1.5, -1.0, -1.0), (1.5, 1.0, 1.0), (-0.8, 0.1, 0.0),
            lambda X: np.sum((X / np.array([1.3, 0.7, 0.7])) ** 2, axis=1) < 1.0,
            lambda X: 0.5 * np.exp(-np.sum((X - np.array([-0.8, 0.0, 0.0])) ** 2, axis=1) / 0.1) + 0.2 * X[:, 0],
            "3-D ellipsoid, a local peak by the start, the optimum on the far edge", role="held-out"),
    Problem("knee-1d", (0.0,), (8.0,), (1.5,), lambda X: (X[:, 0] > 0.5) & (X[:, 0] < 7.0),
            lambda X: 0.8 * np.exp(-((X[:, 0] - 1.6) ** 2) / 0.2) + 0.1 * X[:, 0],
            "1-D, the optimum by the start, R rising slowly toward the far edge but below it", role="seen"),
    # held-out (batch 7): written before far_beta 2.5 was tried on batches 1-6, run once with it and without it;
    # twin-4d (traced to judge its loss) and arc-2d (traced to explain its misses) then seen
    Problem("shelf-1d", (0.0,), (10.0,), (5.5,), lambda X: (X[:, 0] > 1.0) & (X[:, 0] < 9.0),
            lambda X: 0.5 * np.exp(-((X[:, 0] - 5.5) ** 2) / 0.5) + np.exp(-((X[:, 0] - 1.8) ** 2) / 0.8),
            "1-D, a local peak at the start, the optimum near the near edge across a valley", role="held-out"),
    Problem("arc-2d", (-2.5, -2.5), (2.5, 2.5), (-1.5, 0.0),
            lambda X: (np.linalg.norm(X, axis=1) > 1.0) & (np.linalg.norm(X, axis=1) < 2.0) & (X[:, 1] > -0.5),
            _sq((1.5, 0.0)), "2-D arch (non-convex), the optimum at its other foot", role="seen"),
    Problem("twin-4d", (-1.0,) * 4, (1.0,) * 4, (-0.4, 0.0, 0.0, 0.0), _ball((0.0,) * 4, 0.9),
            _two_peaks((-0.4, 0.0, 0.0, 0.0), (0.45, 0.1, -0.1, 0.1), 0.15),
            "4-D ball, a local peak at the start, the optimum across a valley", role="seen"),
    Problem("slope-3d", (-1.0,) * 3, (1.0,) * 3, (0.3, 0.0, 0.0),
            lambda X: np.sum((X / np.array([0.9, 0.7, 0.7])) ** 2, axis=1) < 1.0,
            lambda X: 0.3 * X[:, 0] + 0.9 * np.exp(-np.sum((X - np.array([-0.6, 0.2, 0.0])) ** 2, axis=1) / 0.1),
            "3-D ellipsoid, R rising toward one edge, the optimum a peak behind the start", role="held-out"),
    # held-out (batch 8): written after far_beta 2.5 was made the default, run once with it and without it;
    # cosine-1d then seen: traced, and a classifier fallback (not kept) was tried because of it
    Problem("hump-2d", (-2.0, -2.0), (2.0, 2.0), (-0.9, 0.3), _ball((0.0, 0.0), 1.6),
            lambda X: (0.4 * np.exp(-np.sum((X - np.array([-0.9, 0.3])) ** 2, axis=1) / 0.3)
                       + np.exp(-np.sum((X - np.array([0.8, -0.7])) ** 2, axis=1) / 0.4)),
            "2-D disc, a low hump at the start, the optimum across a valley", role="held-out"),
    Problem("ledge-3d", (-1.0,) * 3, (1.0,) * 3, (-0.5, -0.5, 0.0),
            lambda X: np.all(np.abs(X) < 0.85, axis=1) & (X[:, 0] + X[:, 1] < 1.0),
            lambda X: X[:, 0] + X[:, 1] - 0.5 * X[:, 2] ** 2, "3-D cube cut by a plane, optimum on the cut",
            role="held-out"),
    Problem("cosine-1d", (0.0,), (6.0,), (3.0,), lambda X: (X[:, 0] > 0.5) & (X[:, 0] < 5.5),
            lambda X: 0.5 * np.cos(2.0 * (X[:, 0] - 3.0)) + 0.2 * X[:, 0],
            "1-D, a cosine on a slope: peaks at the start and near the far edge", role="seen"),
    Problem("tube-4d", (-1.0,) * 4, (1.0,) * 4, (-0.6, 0.0, 0.0, 0.0),
            lambda X: (np.abs(X[:, 0]) < 0.9) & np.all(np.abs(X[:, 1:]) < 0.4, axis=1),
            _sq((0.7, 0.1, 0.0, -0.1)), "4-D long box, optimum inside at its far end", role="held-out"),
    # batch 9: written before a bracket look at the edge was tried (not kept), run once with and without it;
    # bend-2d then seen (traced to explain its misses); all four then seen: with batch 10 they chose
    # far_behind 0.25 over 0.5, by a rule written before either was run on them
    Problem("rim-2d", (-2.0, -2.0), (2.0, 2.0), (-0.5, 0.0), _ball((0.0, 0.0), 1.5),
            lambda X: X[:, 0] + 0.3 * X[:, 1], "2-D disc, R a plane: the optimum on the rim", role="seen"),
    Problem("wiggle-1d", (0.0,), (10.0,), (3.0,), lambda X: (X[:, 0] > 1.0) & (X[:, 0] < 7.2),
            lambda X: 0.1 * X[:, 0] + 0.3 * np.sin(X[:, 0]), "1-D, R rising with wiggles to the edge",
            role="seen"),
    Problem("pocket-3d", (-1.0,) * 3, (1.0,) * 3, (-0.3, 0.0, 0.0),
            lambda X: np.sum((X / np.array([0.8, 0.6, 0.6])) ** 2, axis=1) < 1.0,
            _sq((0.2, 0.1, 0.0)), "3-D ellipsoid, optimum inside", role="seen"),
    Problem("bend-2d", (0.0, 0.0), (4.0, 4.0), (0.6, 0.5),
            lambda X: ((X[:, 1] < 1.0) & (X[:, 0] < 3.5)) | ((X[:, 0] > 2.5) & (X[:, 0] < 3.5) & (X[:, 1] < 3.5)),
            lambda X: X[:, 1] + 0.2 * X[:, 0], "2-D L-shaped strip, the optimum at the end of its far arm",
            role="seen"),
    # batch 10: written before CORL spent a budget it would otherwise leave unused (far_ladder, not the default),
    # run once with the default then; seen since: with batch 9 they chose far_behind 0.25 over 0.5
    Problem("plateau-1d", (0.0,), (8.0,), (1.0,), lambda X: (X[:, 0] > 0.5) & (X[:, 0] < 7.5),
            lambda X: np.tanh(2.0 * (X[:, 0] - 4.0)) + 0.05 * X[:, 0],
            "1-D, a low shelf at the start, a high plateau rising slowly to the far edge", role="seen"),
    Problem("kidney-2d", (-2.0, -2.0), (2.0, 2.0), (-1.0, 0.0),
            lambda X: _ball((0.0, 0.0), 1.8)(X) & ~_ball((1.6, 0.0), 0.9)(X),
            _sq((0.9, 1.1)), "2-D disc with a bite out of one side (non-convex), optimum inside the upper lobe",
            role="seen"),
    Problem("corridor-3d", (-1.0,) * 3, (1.0,) * 3, (-0.6, 0.0, 0.0),
            lambda X: ((np.abs(X[:, 0]) < 0.9) & np.all(np.abs(X[:, 1:]) < 0.25, axis=1))
            | _ball((0.6, 0.5, 0.0), 0.35)(X),
            lambda X: X[:, 1] + 0.5 * X[:, 0], "3-D thin corridor with a ball on its side, optimum on the ball's top",
            role="seen"),
    Problem("shell-4d", (-1.0,) * 4, (1.0,) * 4, (-0.3, 0.0, 0.0, 0.0), _ball((0.0,) * 4, 0.85),
            _sq((0.9, 0.45, 0.0, 0.0)), "4-D ball, the optimum on its surface toward a point outside",
            role="seen"),
    # batch 11 (issue 25): the new kinds, written after CORL(budget) and the units-free change and before any
    # change for them; run once, as today's baseline (docs/safe_bo_suite.md, "The new kinds")
    Problem("needle-2d", (0.0, 0.0), (10.0, 10.0), (2.0, 2.0), _strip((2.0, 2.0), (7.5, 6.0), 0.07),
            lambda X: 0.3 * X[:, 0] + 0.2 * X[:, 1], "2-D thin diagonal strip (0.96 % of the box), optimum at its far end",
            role="held-out"),
    Problem("arc-thin-2d", (-2.0, -2.0), (2.0, 2.0), (1.2, 0.0),
            lambda X: (np.abs(np.linalg.norm(X, axis=1) - 1.2) < 0.016) & (X[:, 1] > -0.4),
            lambda X: X[:, 1] - 0.2 * X[:, 0], "2-D thin circular arc (0.9 % of the box), optimum at its top",
            role="held-out"),
    Problem("thin-cross-2d", (-1.0, -1.0), (1.0, 1.0), (-0.7, 0.0),
            lambda X: (np.abs(X[:, 1]) < 0.004) | ((np.abs(X[:, 0] - 0.3) < 0.004) & (X[:, 1] > -0.2)),
            lambda X: X[:, 0] + 1.5 * X[:, 1], "2-D two thin bars crossing (0.5 % of the box), optimum up the second",
            role="held-out"),
    Problem("six-walls-2d", (-3.0, -3.0), (3.0, 3.0), (-1.5, -1.5),
            lambda X: (X[:, 0] + X[:, 1] < 2.0) & (X[:, 0] - X[:, 1] < 1.5) & (X[:, 1] - X[:, 0] < 2.0)
            & (np.linalg.norm(X, axis=1) < 2.6) & ~_ball((0.5, 0.0), 0.6)(X) & (X[:, 0] > -2.5),
            _sq((0.8, 1.0)), "2-D safe set cut by six constraints, optimum on a corner of two", role="held-out"),
    Problem("walls-4d", (-1.0,) * 4, (1.0,) * 4, (-0.2, -0.2, 0.0, 0.0),
            lambda X: _ball((0.0,) * 4, 0.9)(X) & (X[:, 0] + X[:, 1] < 0.8) & (X[:, 2] - X[:, 3] < 0.5)
            & (X[:, 0] - X[:, 2] > -0.9) & (np.abs(X[:, 3]) < 0.6),
            _sq((0.5, 0.4, -0.3, 0.2)), "4-D ball cut by four planes, optimum where two of them meet", role="held-out"),
    Problem("kilonewton-2d", (-2.0, -2.0), (2.0, 2.0), (-0.8, -0.5), _ball((0.0, 0.0), 1.4),
            lambda X: -2e5 + 1e4 * _sq((0.7, 0.6))(X), "2-D disc, returns near -2e5 in steps of 1e4 (units)",
            role="held-out"),
    # 5-7 D training problems (issue 25): written, with batch 12, before any change for 5-7 D, and used to design it
    Problem("sphere-6d", (-1.0,) * 6, (1.0,) * 6, (-0.4, 0.0, 0.0, 0.0, 0.0, 0.0), _ball((0.0,) * 6, 0.85),
            lambda X: X @ np.array([1.0, 0.5, 0.0, 0.0, 0.3, 0.0]), "6-D ball, R a plane: the optimum on its surface",
            known=(0.85 * np.sqrt(1.34), -0.85 * np.sqrt(1.34))),
    Problem("cube-5d", (-1.0,) * 5, (1.0,) * 5, (-0.3, -0.3, 0.0, 0.0, 0.0), lambda X: np.all(np.abs(X) < 0.6, axis=1),
            _sq((0.5, 0.4, -0.3, 0.2, 0.1)), "5-D cube, optimum inside near a corner", known=(0.0, -4.15)),
    Problem("ellipsoid-7d", (-1.0,) * 7, (1.0,) * 7, (-0.2, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            lambda X: np.sum((X / np.array([0.8, 0.7, 0.7, 0.6, 0.6, 0.5, 0.5])) ** 2, axis=1) < 1.0,
            _sq((0.4, -0.3, 0.2, 0.0, 0.1, 0.0, -0.1)), "7-D ellipsoid, optimum inside",  # worst: a bound (-1.73)
            known=(0.0, -(0.8 + np.sqrt(0.31)) ** 2)),
    # batch 12 (issue 25): written before g_S's length scales adapted to a thin safe set and before any change
    # for 5-7 D; held out, run once after them (docs/safe_bo_suite.md, "Thin sets" and "5 to 7 dimensions")
    Problem("slit-1d", (0.0,), (10.0,), (4.03,), lambda X: (X[:, 0] > 4.0) & (X[:, 0] < 4.08),
            lambda X: -((X[:, 0] - 4.07) ** 2), "1-D safe interval of 0.8 % of the box, optimum inside by its edge",
            role="held-out"),
    Problem("thin-ring-2d", (-2.0, -2.0), (2.0, 2.0), (1.0, 0.0),
            lambda X: np.abs(np.linalg.norm(X, axis=1) - 1.0) < 0.012, _sq((-1.3, 0.4)),
            "2-D thin full ring (0.94 % of the box), optimum across it from the start", role="held-out",
            known=(-(np.hypot(1.3, 0.4) - 1.012) ** 2, -(np.hypot(1.3, 0.4) + 1.012) ** 2)),
    Problem("zigzag-2d", (0.0, 0.0), (5.0, 5.0), (0.6, 0.55),
            lambda X: _strip((0.5, 0.5), (2.5, 1.5), 0.015)(X) | _strip((2.5, 1.5), (1.5, 3.5), 0.015)(X)
            | _strip((1.5, 3.5), (4.0, 4.5), 0.015)(X), lambda X: X[:, 0] + X[:, 1],
            "2-D thin zigzag of three bars (0.86 % of the box), optimum at its far end", role="held-out",
            known=(8.5 + 0.015 * np.sqrt(2.0), 1.0 - 0.015 * np.sqrt(2.0))),
    Problem("slit-3d", (-1.0,) * 3, (1.0,) * 3, (-0.3, 0.0, 0.1),
            lambda X: (np.abs(X[:, 2] - 0.1) < 0.008) & (np.linalg.norm(X, axis=1) < 0.9),
            lambda X: X[:, 0] + 0.5 * X[:, 1], "3-D thin disc (0.5 % of the box), optimum on its rim", role="held-out",
            known=(np.sqrt(1.25 * (0.81 - 0.092 ** 2)), -np.sqrt(1.25 * (0.81 - 0.092 ** 2)))),
    Problem("ball-5d", (-1.0,) * 5, (1.0,) * 5, (-0.3, 0.0, 0.0, 0.0, 0.0), _ball((0.0,) * 5, 0.8),
            _sq((0.3, 0.2, -0.1, 0.1, 0.0)), "5-D ball, optimum inside", role="held-out",
            known=(0.0, -(0.8 + np.sqrt(0.15)) ** 2)),
    Problem("cap-6d", (-1.0,) * 6, (1.0,) * 6, (-0.2, -0.2, 0.0, 0.0, 0.0, 0.0),
            lambda X: _ball((0.0,) * 6, 0.9)(X) & (X[:, 0] + X[:, 1] < 0.5),
            lambda X: X[:, 0] + X[:, 1] - 0.5 * np.sum(X[:, 2:] ** 2, axis=1),
            "6-D ball cut by a plane, optimum on the cut", role="held-out", known=(0.5, -0.9 * np.sqrt(2.0))),
    Problem("edge-7d", (-1.0,) * 7, (1.0,) * 7, (0.0,) * 7,
            lambda X: np.sum((X / np.array([0.9, 0.7, 0.6, 0.6, 0.5, 0.5, 0.5])) ** 2, axis=1) < 1.0,
            lambda X: X @ np.array([1.0, 0.5, 0.3, 0.0, 0.0, 0.0, -0.2]), "7-D ellipsoid, optimum on its edge",
            role="held-out", known=(np.sqrt(0.9749), -np.sqrt(0.9749))),
    Problem("megajoule-5d", (-1.0,) * 5, (1.0,) * 5, (-0.3, 0.0, 0.0, 0.0, 0.0), _ball((0.0,) * 5, 0.85),
            lambda X: 3e6 + 2e5 * _sq((0.5, -0.2, 0.1, 0.0, 0.1))(X), "5-D ball, returns near 3e6 in steps of 2e5",
            role="held-out", known=(3e6, 3e6 - 2e5 * (0.85 + np.sqrt(0.31)) ** 2)),
    # batch 13 (issue 32): written before any change for noise, run once at the end
    Problem("disk-2d", (-1.5, -2.5), (3.0, 2.0), (0.3, -1.1), _ball((0.9, -0.6), 1.2), _sq((1.4, 0.3)),
            "2-D disc off the box's centre, a smooth bowl whose optimum is inside near its edge", role="held-out"),
    Problem("notch-2d", (-2.0, -2.0), (2.0, 2.0), (-0.9, -0.5), _notched_disc, _plane_and_bump,
            "2-D disc with a notch cut into its right side (non-convex), a tilted plane plus a bump above the notch",
            role="held-out"),
    Problem("orb-5d", (-1.0,) * 5, (1.0,) * 5, (-0.2, -0.1, 0.0, 0.1, 0.0),
            _ball((0.1, -0.1, 0.0, 0.1, 0.0), 0.75), _sq((0.35, 0.1, -0.2, 0.2, -0.1)),
            "5-D ball off the box's centre, optimum inside", role="held-out",
            known=(0.0, -(0.75 + np.sqrt(0.1625)) ** 2)),  # |optimum - centre|^2 = 0.1625: worst on the far side
]

_GRID = {1: 20001, 2: 401, 3: 71, 4: 29}


@dataclass
class Truth:
    """Dense-grid facts of a problem: optimum, return range, found threshold and a distance-to-safe-set query.

    ``best`` and ``range`` are the highest R and max R - min R in the start's connected safe
    component (worked out by hand for a problem with ``known``).
    """

    best: float
    range: float
    tree: object

    @property
    def tol(self) -> float:
        """How close to ``best`` a return must come to count as found: 2 % of the range."""
        return 0.02 * self.range

    def beyond(self, U: np.ndarray) -> np.ndarray:
        if self.tree is None:  # a problem whose truth was worked out by hand: not measured
            return np.full(len(U), np.nan)
        return self.tree.query(U)[0] if len(U) else np.zeros(0)


def truth_of(p: Problem) -> Truth:
    from scipy import ndimage
    from scipy.spatial import cKDTree

    b, m = p.bounds, p.bounds.dim
    if p.known is not None:  # worked out by hand; no grid of the safe set to measure ``beyond`` on
        best, worst = map(float, p.known)
        assert p.safe(np.array(p.start, float)[None])[0], f"start of {p.name} is not safe"
        return Truth(best, best - worst, None)
    n = _GRID[m]
    axes = [np.linspace(0.0, 1.0, n)] * m
    U = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, m)
    X = b.from_unit(U)
    safe = p.safe(X)
    labels, _ = ndimage.label(safe.reshape((n,) * m))
    start_idx = tuple(np.round(b.to_unit(np.array(p.start)) * (n - 1)).astype(int))
    comp = labels.reshape(-1) == labels[start_idx]
    assert labels[start_idx] > 0, f"start of {p.name} is not safe"
    R = p.ret(X[comp])
    return Truth(float(R.max()), float(R.max() - R.min()), cKDTree(U[safe]))


def rollout(p: Problem, x: np.ndarray) -> Outcome:
    x = np.asarray(x, float).reshape(1, -1)
    if bool(p.safe(x)[0]):
        return Outcome(True, float(p.ret(x)[0]))
    return Outcome(False, None)


class Sensor:
    """What a noisy robot reports of a trial (``--noise``, ``--flip``): a rollout with noise and flipped labels.

    Each call draws one standard normal ``z`` and one uniform ``u`` from ``rng``, whatever the point,
    so the k-th trial of every method meets the same draws. The label is flipped when ``u < flip``;
    a reported success reports ``p.ret(x) + noise_std * z`` (the formula's value also where the
    point is truly unsafe), a reported failure no return. With ``noise_std = flip = 0`` it reports
    what :func:`rollout` does, to the bit.
    """

    def __init__(self, p: Problem, noise_std: float, flip: float, rng: np.random.Generator) -> None:
        self.p, self.noise_std, self.flip, self.rng = p, float(noise_std), float(flip), rng

    @classmethod
    def of_run(cls, p: Problem, truth: Truth, noise: float, flip: float, seed: int, start: int) -> Sensor:
        """The sensor of start number ``start`` of ``p``: noise std ``noise * truth.range``, draws seeded by
        (seed, p's name, start), so the same for every method."""
        rng = np.random.default_rng([seed, zlib.crc32(p.name.encode()), start])
        return cls(p, noise * truth.range, flip, rng)

    def __call__(self, x: np.ndarray) -> Outcome:
        z, u = self.rng.standard_normal(), self.rng.random()
        x = np.asarray(x, float).reshape(1, -1)
        if bool(self.p.safe(x)[0]) == (u < self.flip):  # truly safe and flipped, or truly unsafe and not
            return Outcome(False, None)
        r = float(self.p.ret(x)[0])
        return Outcome(True, r + self.noise_std * z if self.noise_std else r)


def starts_of(p: Problem, k: int, seed: int) -> np.ndarray:
    """The given start, then random safe points near it (within 15 % of the box) for k runs."""
    rng = np.random.default_rng([seed, sum(map(ord, p.name))])
    b = p.bounds
    out = [np.array(p.start, float)]
    while len(out) < k:
        x = np.array(p.start) + 0.15 * b.width * rng.uniform(-1, 1, b.dim)
        if b.contains(x) and p.safe(x[None])[0]:
            out.append(x)
    return np.array(out)


# ---------------------------------------------------------------------------------------------
# Methods: each runner(p, start, budget, seed, sense) returns a Run; ``sense(x)`` is the rollout
# ---------------------------------------------------------------------------------------------
@dataclass
class Run:
    """One run as the method was told it: trials ``X`` (t, m), ``success`` (t,) and ``returns`` (t,)
    (NaN where none was reported) as reported, mean ms per tell + ask, the method's reported best
    ``(theta (m,), value)`` or None, and the one-line message of what it raised (None: it did not)."""

    X: np.ndarray
    success: np.ndarray
    returns: np.ndarray
    ms: float
    best: tuple | None
    error: str | None = None


def _one_line(exc: BaseException) -> str:
    """An exception as one line: corl's own messages as they are, others behind their type."""
    text = " ".join(str(exc).split())
    return (text if isinstance(exc, CorlError) and text else f"{type(exc).__name__}: {text}")[:300]


def _best_reported(X, s, r) -> tuple | None:
    """The reported success with the highest reported return, as ``(theta, value)``, or None."""
    ok = s & np.isfinite(r)
    if not np.any(ok):
        return None
    k = np.flatnonzero(ok)[np.argmax(r[ok])]
    return X[k].copy(), float(r[k])


def _drive(opt, sense, start: np.ndarray, budget: int) -> Run:
    """Tell ``opt`` the start, then ask and tell until it is done or ``budget`` trials are spent.

    What it raises ends the run, which keeps its trials so far and the message (``Run.error``).
    """
    times, error = [], None
    try:
        t0 = time.perf_counter()
        opt.tell(start, sense(start))  # the stopping contract: tell fits and proposes, ask returns it
        while not opt.done and opt.n_evals < budget:
            x = opt.ask()  # never raises before done: the stopping contract
            times.append(time.perf_counter() - t0)
            o = sense(x)
            t0 = time.perf_counter()
            opt.tell(x, o)
    except Exception as exc:  # noqa: BLE001 -- a method that raises is scored (errors), the suite goes on
        error = _one_line(exc)
    try:
        best = opt.best
    except Exception as exc:  # noqa: BLE001 -- a best that cannot be read counts as an error too
        best, error = None, error or _one_line(exc)
    ms = 1e3 * float(np.mean(times)) if times else 0.0
    return Run(opt.X_, opt.success_, opt.returns_, ms, best, error)


def run_corl(p, start, budget, seed, sense):
    return _drive(SafeBOOptimizer(p.bounds, max_evals=budget, seed=seed, start=start), sense, start, budget)


def run_corl_declared(p, start, budget, seed, sense):  # CORL told its sensors' noise: the true std and flip rate
    return _drive(SafeBOOptimizer(p.bounds, max_evals=budget, seed=seed, start=start, label_noise=sense.flip,
                                  return_noise=sense.noise_std or None), sense, start, budget)


def run_corl_budget(p, start, budget, seed, sense):  # CORL(budget): spends every trial, never below the band
    return _drive(SafeBOOptimizer(p.bounds, max_evals=budget, seed=seed, spend_budget=True, start=start), sense, start, budget)


def run_pibu_budget(p, start, budget, seed, sense):  # PIBU(budget): fitted GPs, no stopping rule
    cfg = BOConfig(FITTED_REGRESSION, FITTED_CLASSIFIER, stop_rule=StopRule.BUDGET, distance_scale=tuple(p.bounds.width))
    return _drive(PIBUOptimizer(p.bounds, cfg, max_evals=budget, seed=seed, start=start), sense, start, budget)


def run_pibu(p, start, budget, seed, sense):  # PIBU as a user gets it now: GPs fitted from the data
    cfg = BOConfig(FITTED_REGRESSION, FITTED_CLASSIFIER, distance_scale=tuple(p.bounds.width))
    return _drive(PIBUOptimizer(p.bounds, cfg, max_evals=budget, seed=seed, start=start), sense, start, budget)


def run_pibu_tenth(p, start, budget, seed, sense):  # the baseline: l = box / 10, paper sf and noise
    ls = tuple(0.1 * p.bounds.width)
    cfg = BOConfig(RegressionConfig(lengthscale=ls, signal_std=10.0, noise_std=0.11),
                   ClassifierConfig(lengthscale=ls, signal_std=10.0),
                   distance_scale=tuple(p.bounds.width))
    return _drive(PIBUOptimizer(p.bounds, cfg, max_evals=budget, seed=seed, start=start), sense, start, budget)


def botorch_step(b: Bounds, X, s, r, seed: int):
    """One constrained LogEI step: GP on successful returns, GP constraint on labels (+-1) >= 0."""
    import torch
    from botorch.acquisition.analytic import LogConstrainedExpectedImprovement
    from botorch.fit import fit_gpytorch_mll
    from botorch.models import ModelListGP, SingleTaskGP
    from botorch.models.transforms import Standardize
    from botorch.optim import optimize_acqf
    from gpytorch.mlls import ExactMarginalLogLikelihood

    torch.manual_seed(seed)
    U = torch.tensor(b.to_unit(X), dtype=torch.float64)
    ok = torch.tensor(s)
    y = torch.tensor(np.where(s, r, 0.0), dtype=torch.float64)[:, None]
    c = torch.tensor(np.where(s, 1.0, -1.0), dtype=torch.float64)[:, None]
    f_gp = SingleTaskGP(U[ok], y[ok], outcome_transform=Standardize(m=1))
    c_gp = SingleTaskGP(U, c)
    for gp in (f_gp, c_gp):
        try:
            fit_gpytorch_mll(ExactMarginalLogLikelihood(gp.likelihood, gp))
        except Exception:  # noqa: BLE001 -- a failed fit keeps BoTorch's default hyperparameters
            pass
    model = ModelListGP(f_gp, c_gp)
    acq = LogConstrainedExpectedImprovement(model, best_f=float(y[ok].max()), objective_index=0,
                                            constraints={1: (0.0, None)})
    m = b.dim
    box = torch.stack([torch.zeros(m), torch.ones(m)]).double()
    cand, _ = optimize_acqf(acq, bounds=box, q=1, num_restarts=4, raw_samples=128)
    return b.from_unit(cand.detach().numpy().reshape(m))


class BoTorchLogEI:
    """:func:`botorch_step` behind ask/tell, so :func:`_drive` runs it as it runs corl's methods.

    It spends the whole budget; its reported best is its best reported success.
    """

    def __init__(self, bounds: Bounds, budget: int, seed: int) -> None:
        self.bounds, self.budget, self.seed = bounds, budget, seed
        self.X_, self.success_, self.returns_ = np.empty((0, bounds.dim)), np.empty(0, bool), np.empty(0)

    def tell(self, x, outcome: Outcome) -> None:
        self.X_ = np.vstack([self.X_, np.asarray(x, float)])
        self.success_ = np.append(self.success_, outcome.success)
        self.returns_ = np.append(self.returns_, np.nan if outcome.return_ is None else outcome.return_)

    def ask(self) -> np.ndarray:
        if not self.success_.any():
            raise RuntimeError("constrained LogEI needs a reported success for its incumbent; none was reported")
        return botorch_step(self.bounds, self.X_, self.success_, self.returns_, self.seed + self.n_evals)

    @property
    def done(self) -> bool:
        return self.n_evals >= self.budget

    @property
    def n_evals(self) -> int:
        return len(self.X_)

    @property
    def best(self) -> tuple | None:
        return _best_reported(self.X_, self.success_, self.returns_)


def run_botorch(p, start, budget, seed, sense):
    return _drive(BoTorchLogEI(p.bounds, budget, seed), sense, start, budget)


_SAFEOPT_WORKER = r'''
import collections, collections.abc, json, sys, time
for _n in ("Sequence", "Iterable", "Mapping"):  # safeopt 0.16 predates Python 3.10
    setattr(collections, _n, getattr(collections.abc, _n))
import numpy as np
np.float, np.int, np.bool = float, int, bool  # ... and numpy 1.24
import GPy, safeopt
for line in sys.stdin:
    job = json.loads(line)
    m, budget, start, n = job["m"], job["budget"], np.array(job["start"]), job["grid"]
    grid = safeopt.linearly_spaced_combinations([(0.0, 1.0)] * m, [n] * m)
    grid = np.vstack([grid, start[None]])  # the start is safe: SafeOpt's set must contain it
    r0 = job["r0"]; scale = abs(r0) if r0 else 1.0
    kf = GPy.kern.RBF(m, variance=1.0, lengthscale=0.2, ARD=False)
    kc = GPy.kern.RBF(m, variance=1.0, lengthscale=0.1, ARD=False)
    x0 = start[None]
    gpf = GPy.models.GPRegression(x0, np.array([[r0 / scale]]), kf, noise_var=1e-3)
    # labels +-1 are a step: with tiny noise, nearby opposite labels make the interpolant ring
    # (means of +-20 far away) and SafeOpt then calls distant points safe; noise 0.1 damps it
    gpc = GPy.models.GPRegression(x0, np.array([[1.0]]), kc, noise_var=0.1)
    opt = safeopt.SafeOpt([gpf, gpc], grid, fmin=[-np.inf, 0.0], beta=2.0, threshold=np.array([-np.inf, 0.0]))
    times, out = [], []
    for _ in range(budget - 1):
        t0 = time.perf_counter()
        try:
            x = opt.optimize()
        except Exception:
            break
        times.append(time.perf_counter() - t0)
        sys.stdout.write(json.dumps({"x": list(map(float, x))}) + "\n"); sys.stdout.flush()
        res = json.loads(sys.stdin.readline())
        y = np.array([[res["r"] / scale if res["ok"] else np.nan, 1.0 if res["ok"] else -1.0]])
        opt.add_new_data_point(x, y)
    sys.stdout.write(json.dumps({"done": True, "ms": 1e3 * float(np.mean(times)) if times else 0.0}) + "\n")
    sys.stdout.flush()
'''


def make_safeopt_runner(python: str):
    proc = subprocess.Popen([python, "-c", _SAFEOPT_WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})

    def run(p, start, budget, seed, sense):
        b = p.bounds
        u0 = b.to_unit(np.array(start))
        o0 = sense(np.array(start))
        X, s, r = [np.array(start)], [o0.success], [np.nan if o0.return_ is None else o0.return_]
        if not o0.success:  # its safe seed: SafeOpt cannot begin from a start reported as a failure
            return Run(np.array(X), np.array(s), np.array(r), 0.0, None,
                       "SafeOpt needs its start to succeed (its safe seed); the start was reported as a failure")
        grid = {1: 200, 2: 40, 3: 12, 4: 7}[b.dim]  # SafeOpt scores every grid point per expander
        proc.stdin.write(json.dumps({"m": b.dim, "budget": budget, "start": u0.tolist(), "r0": o0.return_,
                                     "grid": grid}) + "\n")
        proc.stdin.flush()
        while True:
            msg = json.loads(proc.stdout.readline())
            if "done" in msg:
                X, s, r = np.array(X), np.array(s), np.array(r)
                return Run(X, s, r, msg["ms"], _best_reported(X, s, r))
            x = b.from_unit(np.array(msg["x"]))
            o = sense(x)
            X.append(x), s.append(o.success), r.append(np.nan if o.return_ is None else o.return_)
            proc.stdin.write(json.dumps({"ok": o.success, "r": o.return_}) + "\n")
            proc.stdin.flush()

    return run


# ---------------------------------------------------------------------------------------------
# The runs: one task per (problem, method), in this process or in --jobs processes
# ---------------------------------------------------------------------------------------------
_RUNNERS = {"CORL": run_corl, "PIBU": run_pibu, "PIBU(l=w/10)": run_pibu_tenth, "CORL(budget)": run_corl_budget,
            "PIBU(budget)": run_pibu_budget, "BoTorch": run_botorch, "CORL(declared)": run_corl_declared}
_SAFEOPT: dict[str, Callable] = {}  # interpreter -> runner: one SafeOpt process per process of the suite


@dataclass(frozen=True)
class Task:
    """The runs of one method on one problem: starts ``first`` to ``last - 1`` of ``starts_of(p, count, seed)``.

    ``noise`` and ``flip``: the :class:`Sensor`'s levels (0, 0: a clean run); ``safeopt_python``:
    the interpreter SafeOpt runs in.
    """

    problem: str
    method: str
    count: int
    first: int
    last: int
    budget: int
    seed: int
    noise: float = 0.0
    flip: float = 0.0
    safeopt_python: str | None = None


def problem_named(name: str) -> Problem:
    return next(p for p in PROBLEMS if p.name == name)


@functools.lru_cache(maxsize=4)  # tasks come problem by problem: a grid is taken once per problem and process
def _truth(name: str) -> Truth:
    return truth_of(problem_named(name))


def _runner(method: str, safeopt_python: str | None) -> Callable:
    if method != "SafeOpt":
        return _RUNNERS[method]
    if safeopt_python not in _SAFEOPT:
        _SAFEOPT[safeopt_python] = make_safeopt_runner(safeopt_python)
    return _SAFEOPT[safeopt_python]


def run_task(task: Task) -> list[dict]:
    """The ``--json`` record of each run of ``task``, scored by :func:`score` (clean: no noise, no flip)."""
    p, truth = problem_named(task.problem), _truth(task.problem)
    runner = _runner(task.method, task.safeopt_python)
    clean = task.noise == 0 and task.flip == 0
    records = []
    for i, x0 in list(enumerate(starts_of(p, task.count, task.seed)))[task.first:task.last]:
        sense = Sensor.of_run(p, truth, task.noise, task.flip, task.seed, i)
        try:
            run = runner(p, x0, task.budget, task.seed + i, sense)
        except Exception as exc:  # noqa: BLE001 -- raised before any trial (a constructor, SafeOpt's process)
            run = Run(np.empty((0, p.bounds.dim)), np.empty(0, bool), np.empty(0), 0.0, None, _one_line(exc))
        records.append({"problem": p.name, "method": task.method, "start": i, **score(p, truth, run, clean),
                        "ms": run.ms, "noise": task.noise, "flip": task.flip})
    return records


def run_tasks(tasks: list[Task], jobs: int = 1):
    """``(task, records)`` as each task finishes: in order here for ``jobs`` 1, else from ``jobs`` processes.

    A task's numbers depend on nothing but the task (its seeds, its sensor), so they are the same either way.
    """
    if jobs == 1:
        for task in tasks:
            yield task, run_task(task)
        return
    with ProcessPoolExecutor(jobs) as pool:
        futures = {pool.submit(run_task, task): task for task in tasks}
        for done in as_completed(futures):
            yield futures[done], done.result()


# ---------------------------------------------------------------------------------------------
# The table
# ---------------------------------------------------------------------------------------------
def score(p: Problem, truth: Truth, run: Run, clean: bool = True) -> dict:
    """One run's record: found, fail, beyond, trials, and the TRUE scores within5, true_fail, unsafe_best, error.

    ``clean`` (no noise, no flip): found and beyond from the reported data, as always. Otherwise
    found asks whether a truly safe trial's TRUE return came within 2 % of the range of the
    optimum, and beyond measures the truly unsafe trials. ``fail`` is always the failures reported.
    """
    X, s, r = run.X, run.success, run.returns
    safe = p.safe(X) if len(X) else np.zeros(0, bool)  # the TRUE S of every trial
    if clean:
        ok, value, unsafe = s & np.isfinite(r), r, ~s
    else:
        ok, value, unsafe = safe, (p.ret(X) if len(X) else np.zeros(0)), ~safe
    fails = X[unsafe]
    beyond = truth.beyond(p.bounds.to_unit(fails)) if len(fails) else np.zeros(1)
    if truth.tree is None:  # a truth worked out by hand: the distance is not measured, with or without failures
        beyond = np.full(1, np.nan)
    found = bool(ok.any()) and float(np.max(value[ok])) >= truth.best - truth.tol
    within5 = unsafe_best = False  # the reported best, judged by the TRUE S and R (nothing reported: neither)
    if run.best is not None:
        theta = np.asarray(run.best[0], float).reshape(1, -1)
        unsafe_best = not bool(p.safe(theta)[0])
        within5 = not unsafe_best and float(p.ret(theta)[0]) >= truth.best - 0.05 * truth.range
    return {"found": found, "fail": int(np.sum(~s)), "beyond": float(np.max(beyond)), "trials": len(X),
            "within5": within5, "true_fail": int(np.sum(~safe)), "unsafe_best": unsafe_best, "error": run.error}


_SPEED_LAYOUTS = ("uniform", "clustered")
_SPEED_PROBLEMS = {2: "inside-2d", 5: "cube-5d"}  # by name: a problem added before them must not move a figure


def speed_problem(dim: int) -> Problem:
    """The problem a timed iteration is set on: inside-2d in 2-D (as always), cube-5d in 5-D, else the first in m-D.

    cube-5d: a cube of half-width 0.6 in [-1, 1]^5, the optimum inside (a training problem: the
    held-out ones stay out of everything but their one run). Only its box, safe set and returns are
    used, on points of :func:`speed_data`.
    """
    for p in PROBLEMS:
        if p.bounds.dim == dim and p.name == _SPEED_PROBLEMS.get(dim, p.name):
            return p
    raise ValueError(f"no problem of the suite has {dim} dimensions (the suite has "
                     f"{sorted({p.bounds.dim for p in PROBLEMS})})")


def speed_data(p: Problem, n: int, seed: int = 0, layout: str = "uniform", fail_share: float = 0.15):
    """``n`` points on ``p`` with success labels and returns (NaN on failure): ``(X, s, r)``.

    ``uniform``: n random points in the box, the layout of the 2-D figure reported until now (on
    inside-2d about 72 % of them fail). ``clustered``, as a safe-BO run at that size has them: the
    start, then successes drawn around it in a spread that widens as the run goes on (a normal of
    4 % of the box width for the first, 29 % for the last; an unsafe or out-of-box draw is drawn
    again), then ``round(fail_share * n)`` failures just outside the safe set where the run probed
    it: on the ray from the start through a random success, 1-10 % of the box width (unit-box
    units, as ``beyond``) past the edge of the safe set. The points after the start are shuffled.
    """
    if layout not in _SPEED_LAYOUTS:
        raise ValueError(f"layout must be one of {_SPEED_LAYOUTS}, got {layout!r}")
    rng = np.random.default_rng(seed)
    b, m = p.bounds, p.bounds.dim
    if layout == "uniform":
        X = b.from_unit(rng.random((n, m)))
        s = p.safe(X)
        return X, s, np.where(s, p.ret(X), np.nan)

    def safe(U):
        return p.safe(b.from_unit(np.atleast_2d(U)))

    u0 = b.to_unit(np.array(p.start, float))
    n_fail = min(int(round(fail_share * n)), max(n - 2, 0))
    n_ok = n - n_fail
    ok, tries = [u0], 0
    while len(ok) < n_ok:
        tries += 1
        if tries > 10_000 * n:
            raise RuntimeError(f"{p.name}: too few safe draws around the start for {n_ok} successes")
        u = u0 + (0.04 + 0.25 * len(ok) / max(n_ok - 1, 1)) * rng.standard_normal(m)
        if np.all((u >= 0.0) & (u <= 1.0)) and safe(u)[0]:
            ok.append(u)
    ok, fails, tries = np.array(ok), [], 0
    while len(fails) < n_fail:
        tries += 1
        if tries > 1_000 * n:
            raise RuntimeError(f"{p.name}: no failure just outside the safe set could be placed")
        d = ok[rng.integers(1, n_ok)] - u0
        if not np.linalg.norm(d):
            continue
        d = d / np.linalg.norm(d)
        lo, hi = 0.0, 2.0 * np.sqrt(m)  # from the start (safe) to well outside the unit box
        if safe(u0 + hi * d)[0]:
            continue
        for _ in range(40):  # the edge of the safe set on this ray
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if safe(u0 + mid * d)[0] else (lo, mid)
        u = u0 + (hi + rng.uniform(0.01, 0.10)) * d
        if np.all((u >= 0.0) & (u <= 1.0)) and not safe(u)[0]:
            fails.append(u)
    U = np.vstack([ok, np.array(fails).reshape(-1, m)])
    U = U[np.concatenate([[0], 1 + rng.permutation(len(U) - 1)])]
    X = b.from_unit(U)
    s = p.safe(X)
    return X, s, np.where(s, p.ret(X), np.nan)


def _stats(times) -> dict:
    ms = 1e3 * np.asarray(times, float)
    return {"median": float(np.median(ms)), "min": float(ms.min()), "max": float(ms.max()), "all": ms.tolist()}


def speed(n: int = 100, seed: int = 0, *, dim: int = 2, layout: str = "uniform", repeats: int = 5,
          threads: int = 1) -> dict:
    """ms of one iteration at n points in ``dim``-D: CORL's and BoTorch's, each the median of ``repeats``.

    The points: :func:`speed_data` (``layout``) on :func:`speed_problem` (``dim``); by default 100
    uniform points on inside-2d, the figure reported since the first.

    CORL: the n-th point is told and the next decision made (``done``): both GPs fitted,
    warm-started from the fit at n - 1 points as in a run, and SEIB maximised with every look the
    decision needs (``CORL_stops``: it decided to stop, which asks the looks beyond the band and
    far too). The repeats must decide alike (the same stop, or the same next point), else
    ``RuntimeError``. Its BLAS threads are this process's (``OPENBLAS_NUM_THREADS``).
    BoTorch (:func:`botorch_step`): both GPs fitted and ``optimize_acqf``; one untimed call first
    (torch's first calls pay one-off costs), then ``repeats`` timed, seeds ``seed + k``, with
    ``torch.set_num_threads(threads)`` (restored after). ``BoTorch`` is None, and ``BoTorch_skip``
    says why, when torch or botorch cannot be imported.

    ``CORL`` and ``BoTorch`` are medians; ``*_min``, ``*_max`` and ``*_all`` (ms) go with them.
    """
    p = speed_problem(dim)
    X, s, r = speed_data(p, n, seed, layout)
    out = {"problem": p.name, "dim": dim, "n": n, "layout": layout, "successes": int(s.sum()),
           "failures": int((~s).sum()), "repeats": repeats, "threads": threads, "blas": _blas_threads(),
           "torch_threads": None}
    times, decisions = [], []
    for _ in range(max(int(repeats), 1)):
        opt = SafeBOOptimizer(p.bounds, max_evals=10 * n, seed=seed)
        for x in X[:-1]:
            opt.tell(x, rollout(p, x))
        opt.done  # the fit at n - 1 points and its decision (not timed): the warm start, as in a run
        t0 = time.perf_counter()
        opt.tell(X[-1], rollout(p, X[-1]))  # not asked, so the decision is made again
        opt.done
        times.append(time.perf_counter() - t0)
        decisions.append(opt.stop_reason or tuple(float(v) for v in opt.ask()))  # after the clock
    if len(set(decisions)) != 1:  # the same data and seed: a timing over different work would mean nothing
        raise RuntimeError(f"the {len(decisions)} timed CORL decisions differ ({decisions}); the timing is not "
                           "comparable")
    st = _stats(times)
    out.update({"CORL": st["median"], "CORL_min": st["min"], "CORL_max": st["max"], "CORL_all": st["all"]})
    out["CORL_stops"] = isinstance(decisions[0], StopReason)
    out["CORL_decision"] = decisions[0].value if out["CORL_stops"] else "proposal"
    out.update({"BoTorch": None, "BoTorch_skip": None})
    try:
        import torch

        before = torch.get_num_threads()
        torch.set_num_threads(threads)  # as many as CORL's BLAS has: run with OPENBLAS_NUM_THREADS=threads
        out["torch_threads"] = torch.get_num_threads()
        try:
            botorch_step(p.bounds, X, s, r, seed - 1)  # warm-up, not timed
            times = []
            for k in range(max(int(repeats), 1)):
                t0 = time.perf_counter()
                botorch_step(p.bounds, X, s, r, seed + k)
                times.append(time.perf_counter() - t0)
        finally:
            torch.set_num_threads(before)
        st = _stats(times)
        out.update({"BoTorch": st["median"], "BoTorch_min": st["min"], "BoTorch_max": st["max"],
                    "BoTorch_all": st["all"]})
    except ImportError as exc:
        out["BoTorch_skip"] = f"{type(exc).__name__}: {exc}"
    return out


def _blas_threads() -> str:
    """The BLAS/OpenMP thread pools loaded in this process and their sizes (threadpoolctl), or the env."""
    env = ", ".join(f"{k}={os.environ[k]}" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
                    if k in os.environ) or "no *_NUM_THREADS set"
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return f"{env} (threadpoolctl not installed: pools not listed)"
    pools = [f"{i.get('internal_api')}[{Path(i.get('filepath', '?')).name.split('.')[0]}]={i.get('num_threads')}"
             for i in threadpool_info()]
    return f"{env}; pools: {', '.join(pools) or 'none'}"


def speed_versions() -> str:
    """corl (with its git commit) and the libraries the timings depend on, as this interpreter has them."""
    from importlib import metadata
    import platform

    repo = Path(__file__).resolve().parents[1]
    try:
        version = metadata.version("corl")
    except metadata.PackageNotFoundError:
        version = "not installed"
    try:
        head = subprocess.run(["git", "-C", str(repo), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(repo), "status", "--porcelain", "--", "src"], capture_output=True,
                               text=True, timeout=10).stdout.split("\n")
        dirty = [line[3:].removeprefix("src/") for line in dirty if line.strip()]
        git = f", git {head}" + (f" + uncommitted changes in src/: {', '.join(dirty)}" if dirty else "") if head else ""
    except (OSError, subprocess.SubprocessError):
        git = ""
    parts = [f"corl {version} (imported from {repo / 'src'}{git})"]
    for name in ("numpy", "scipy", "torch", "botorch", "gpytorch", "linear_operator"):
        try:
            mod = __import__(name)
            parts.append(f"{name} {getattr(mod, '__version__', None) or metadata.version(name)}")
        except ImportError:
            parts.append(f"{name} not installed")
    return (", ".join(parts) + f"; Python {platform.python_version()} ({sys.executable}), "
            f"{platform.system()} {platform.machine()}, {os.cpu_count()} CPUs")


def parse_speed_case(spec: str) -> tuple[int, int, str]:
    """``DxN`` or ``DxN:LAYOUT`` (``5x200``, ``2x100:uniform``) -> (D, N, LAYOUT); the layout defaults to clustered."""
    import re

    m = re.fullmatch(r"(\d+)x(\d+)(?::(\w+))?", spec.strip())
    if not m or (m.group(3) or "clustered") not in _SPEED_LAYOUTS or int(m.group(2)) < 4:
        raise ValueError(f"a --speed case is DxN or DxN:LAYOUT with N >= 4 and LAYOUT one of {_SPEED_LAYOUTS}, "
                         f"got {spec!r}")
    return int(m.group(1)), int(m.group(2)), m.group(3) or "clustered"


def speed_rows(cases, threads=(1,), repeats: int = 5, seed: int = 0) -> list[dict]:
    """:func:`speed` of every case at every thread count.

    A thread count equal to this process's ``OPENBLAS_NUM_THREADS`` runs here; any other in a fresh
    interpreter with ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` set to it
    (a BLAS reads them when it loads).
    """
    rows = []
    for k in threads:
        if os.environ.get("OPENBLAS_NUM_THREADS") == str(k):
            rows += [speed(n, seed, dim=d, layout=lay, repeats=repeats, threads=k) for d, n, lay in cases]
            continue
        job = json.dumps({"cases": [list(c) for c in cases], "threads": k, "repeats": repeats, "seed": seed})
        env = {**os.environ, "OPENBLAS_NUM_THREADS": str(k), "OMP_NUM_THREADS": str(k), "MKL_NUM_THREADS": str(k)}
        done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--speed-worker", job], env=env,
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f"the speed run at {k} threads failed ({done.returncode}):\n{done.stderr[-3000:]}")
        rows += json.loads(done.stdout.strip().splitlines()[-1])
    return rows


def print_speed(rows, versions: str) -> None:
    """The speed table: one row per case and thread count, then what was timed, the threads and the versions."""
    reps = sorted({r["repeats"] for r in rows})
    print(f"\nOne iteration at n points, CORL and BoTorch on the same points: median ms of {'/'.join(map(str, reps))} "
          "repeats (min-max)")
    print(f"{'case':<50} {'thr':>3} {'CORL ms':>22} {'CORL decides':<15} {'BoTorch ms':>22} {'BoTorch/CORL':>12}")
    print("-" * 130)
    for r in rows:
        case = f"{r['dim']}-D {r['problem']}, {r['n']} pts {r['layout']} ({r['successes']} ok, {r['failures']} fail)"
        corl = f"{r['CORL']:.1f} ({r['CORL_min']:.1f}-{r['CORL_max']:.1f})"
        if r["BoTorch"] is None:
            bt, ratio = "skipped", ""
        else:
            bt = f"{r['BoTorch']:.1f} ({r['BoTorch_min']:.1f}-{r['BoTorch_max']:.1f})"
            ratio = f"{r['BoTorch'] / r['CORL']:.1f}x"
        print(f"{case:<50} {r['threads']:>3} {corl:>22} {r['CORL_decision']:<15} {bt:>22} {ratio:>12}")
    print("\nCORL   : tell the n-th point and decide (SafeBOOptimizer: g_R and g_S fitted with their hyperparameters, "
          "warm-started\n         from the fit at n - 1 points as in a run; SEIB maximised with every staged look the "
          "decision needs)")
    print("BoTorch: botorch_step: a SingleTaskGP on the returns and one on the +-1 labels, both fitted from scratch "
          "(fit_gpytorch_mll),\n         LogConstrainedExpectedImprovement by optimize_acqf (4 restarts, 128 raw "
          "samples); one untimed call before the repeats")
    print("threads: thr = OPENBLAS_NUM_THREADS (and OMP_/MKL_) of the timing process for CORL and torch.set_num_threads"
          "(thr) inside\n         the BoTorch timing; a thr other than this process's OPENBLAS_NUM_THREADS ran in a "
          "subprocess set so")
    for k in sorted({r["threads"] for r in rows}):
        r = next(r for r in rows if r["threads"] == k)
        torch_threads = "" if r["torch_threads"] is None else f"; torch.get_num_threads() in BoTorch's timing: " \
            f"{r['torch_threads']}"
        print(f"  thr {k}: when CORL was timed: {r['blas']}{torch_threads}")
        if k > 1 and (r["blas"].count("openblas[") > 1 or "not listed" in r["blas"]):
            print(f"         (numpy and scipy may each load an OpenBLAS: {k} threads each, on {os.cpu_count()} CPUs, "
                  "can contend and slow CORL)")
    skipped = {r["BoTorch_skip"] for r in rows if r["BoTorch_skip"]}
    if skipped:
        print(f"BoTorch skipped: torch/botorch cannot be imported here ({'; '.join(sorted(skipped))}); "
              "pip install 'corl-skills[bench]'")
    print(f"versions: {versions}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--starts", type=int, default=20)
    ap.add_argument("--peer-starts", type=int, default=None, help="starts for the peers (default --starts)")
    ap.add_argument("--start-range", default=None, metavar="A:B",
                    help="run only starts A..B-1 of each problem's list (to split a long peer run)")
    ap.add_argument("--budget", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--methods", default="CORL,PIBU,PIBU(l=w/10),BoTorch,SafeOpt")
    ap.add_argument("--problems", default=None, help="comma-separated names (default all)")
    ap.add_argument("--noise", type=float, default=None, metavar="F",
                    help="report every success's return with Gaussian noise of std F times the problem's return "
                         "range, and score against the TRUE R and S (default: no noise)")
    ap.add_argument("--flip", type=float, default=None, metavar="Q",
                    help="report each trial's success label wrong with probability Q, and score against the TRUE "
                         "R and S (default: no flip)")
    ap.add_argument("--jobs", type=int, default=1, metavar="N",
                    help="run the (problem, method) pairs in N processes (the same numbers as one)")
    local = Path(__file__).resolve().parents[1] / ".venv-safeopt" / "bin" / "python"
    ap.add_argument("--safeopt-python", default=os.environ.get("CORL_SAFEOPT_PYTHON", str(local)),
                    help="an interpreter with safeopt installed (default $CORL_SAFEOPT_PYTHON)")
    ap.add_argument("--speed", nargs="*", default=None, metavar="DxN[:LAYOUT]",
                    help="also time one iteration of CORL and of BoTorch: alone, at 100 uniform points in 2-D (as "
                         "always); else at each case given, D dimensions and N points, LAYOUT clustered (default: "
                         "a run's points around the start, 15 %% failing just outside the safe set) or uniform, "
                         "e.g. --speed 2x100:uniform 5x200")
    ap.add_argument("--speed-only", action="store_true", help="time only (--speed's cases): run no problem")
    ap.add_argument("--speed-threads", default="1", metavar="K[,K...]",
                    help="thread counts to time at (default 1): OpenBLAS threads for CORL, torch threads for BoTorch; "
                         "one other than this process's OPENBLAS_NUM_THREADS runs in a subprocess")
    ap.add_argument("--speed-repeats", type=int, default=5, help="timed repeats per method and case (median)")
    ap.add_argument("--speed-worker", default=None, help=argparse.SUPPRESS)  # one thread count, in a subprocess
    ap.add_argument("--json", default=None, help="write every run's numbers here")
    ap.add_argument("--table", nargs="+", default=None, metavar="JSON",
                    help="run nothing: print the table of runs saved with --json (several files are merged; a "
                         "start saved in two files counts once, from the later file)")
    ap.add_argument("--markdown", action="store_true", help="with --table: a Markdown table")
    ap.add_argument("--verdict", action="store_true",
                    help="with --table: CORL beside the best-finding and the least-failing peer on each problem, "
                         "and on how many problems it finds as often and fails less")
    ap.add_argument("--trade-off", default=None, metavar="PNG",
                    help="with --table: plot optima found against failures per run, one point per method (or "
                         "LABEL=FILE), over the problems every one of them ran, and print the points")
    ap.add_argument("--compare", nargs=2, default=None, metavar=("BEFORE", "AFTER"),
                    help="run nothing: CORL's runs in two --json files side by side, per problem")
    args = ap.parse_args(argv)
    if args.speed_worker:  # speed_rows' subprocess: its cases at its thread count, as JSON on the last line
        job = json.loads(args.speed_worker)
        rows = [speed(n, job["seed"], dim=d, layout=lay, repeats=job["repeats"], threads=job["threads"])
                for d, n, lay in job["cases"]]
        print(json.dumps(rows))
        return
    if args.speed_only and args.speed is None:
        args.speed = []
    if args.speed is not None:
        try:
            speed_cases = [parse_speed_case(c) for c in args.speed] or [(2, 100, "uniform")]
            for d, _, _ in speed_cases:
                speed_problem(d)  # a dimension the suite has
            speed_threads = [int(k) for k in args.speed_threads.split(",") if k.strip()]
        except ValueError as exc:
            ap.error(str(exc))
        if not speed_threads or min(speed_threads) < 1 or args.speed_repeats < 1:
            ap.error("--speed-threads needs counts >= 1 and --speed-repeats at least 1")
    if args.speed_only:
        _report_speed(speed_cases, speed_threads, args.speed_repeats, args.seed)
        return
    if (args.verdict or args.trade_off) and not args.table:
        ap.error("--verdict and --trade-off read saved runs: give them with --table FILE...")
    if args.compare and args.table:
        ap.error("--compare and --table are two reports: give one")
    if args.compare:
        print_compare(*args.compare, markdown=args.markdown)
        return
    if args.table and args.trade_off:
        plot_trade_off(args.table, args.trade_off, args.budget, markdown=args.markdown)
        return
    if args.table:
        (print_verdict if args.verdict else print_table)(args.table, args.budget, markdown=args.markdown)
        return

    noise, flip = args.noise or 0.0, args.flip or 0.0
    if not (0.0 <= noise < np.inf and 0.0 <= flip <= 1.0) or args.jobs < 1:
        ap.error(f"--noise must be a finite share >= 0 (got {noise}), --flip a probability in [0, 1] (got {flip}) "
                 f"and --jobs at least 1 (got {args.jobs})")
    levels = [(noise, flip)] if args.noise is not None or args.flip is not None else None  # rows with the TRUE scores
    wanted = [m.strip() for m in args.methods.split(",") if m.strip()]
    available = set(_RUNNERS) - {"BoTorch"}
    if "BoTorch" in wanted:
        if importlib.util.find_spec("botorch") is not None:  # not imported here: --jobs forks this process
            available.add("BoTorch")
        else:
            print("BoTorch: not installed (pip install 'corl-skills[bench]'), skipped")
    if "SafeOpt" in wanted:
        if args.safeopt_python and Path(args.safeopt_python).exists():
            available.add("SafeOpt")
        else:
            print("SafeOpt: no interpreter with safeopt (--safeopt-python), skipped")
    methods = [m for m in wanted if m in available]
    problems = [p for p in PROBLEMS if args.problems is None or p.name in args.problems.split(",")]

    tasks = []
    for p in problems:
        for name in methods:
            k = args.starts if name in CORL_METHODS or args.peer_starts is None else args.peer_starts
            first, last = (0, k) if args.start_range is None else map(int, args.start_range.split(":"))
            tasks.append(Task(p.name, name, max(k, last), first, last, args.budget, args.seed, noise, flip,
                              args.safeopt_python if name == "SafeOpt" else None))
    done = {}
    for task, recs in run_tasks(tasks, args.jobs):
        done[task] = recs
        print(_row(problem_named(task.problem), task.method, recs, levels is not None), flush=True)
    print()
    print(_table_title(args.budget, levels))
    for task in tasks:
        print(_row(problem_named(task.problem), task.method, done[task], levels is not None))
    records = [rec for task in tasks for rec in done[task]]
    if args.speed is not None:
        _report_speed(speed_cases, speed_threads, args.speed_repeats, args.seed)
    if args.json:
        Path(args.json).write_text(json.dumps(records, indent=1))


def _report_speed(cases, threads, repeats: int, seed: int) -> None:
    """``--speed``: the table of :func:`print_speed`, and the one line it printed before for 2-D, 100 uniform points."""
    rows = speed_rows(cases, threads, repeats, seed)
    print_speed(rows, speed_versions())
    for sp in rows:
        if (sp["dim"], sp["n"], sp["layout"]) == (2, 100, "uniform") and sp["threads"] == min(threads):
            bt = "not installed" if sp["BoTorch"] is None else f"{sp['BoTorch']:.0f} ms"
            ratio = "" if sp["BoTorch"] is None else f" ({sp['BoTorch'] / sp['CORL']:.0f}x)"
            how = "a decision to stop: every look" if sp["CORL_stops"] else "a proposal"
            print(f"\none iteration at 100 points in 2-D: CORL {sp['CORL']:.0f} ms ({how}), BoTorch {bt}{ratio}"
                  f" (medians, {sp['threads']} thread)")


def _labelled(arg) -> tuple[str | None, str]:
    """``LABEL=FILE`` -> (LABEL, FILE); a FILE that exists (its name may hold "=") -> (None, FILE).

    The label ends at the first "=" after which an existing file is named; when none is, the
    whole argument is taken as a file name (and reported as one that cannot be read).
    """
    arg = str(arg)
    if Path(arg).exists():
        return None, arg
    for i, ch in enumerate(arg):
        if ch == "=" and i > 0 and Path(arg[i + 1:]).exists():
            return arg[:i], arg[i + 1:]
    return None, arg


def load_runs(paths) -> dict:
    """``{(problem, method): {start: record}}`` from ``--json`` files, merged (a start saved twice: the last).

    A path given as ``LABEL=FILE`` names every run in that file ``LABEL`` instead of its method (two
    settings of CORL side by side): such a file must hold one method, and no other file may hold a
    method of that name (runs would be mixed silently).
    """
    runs: dict = {}
    names = {p.name for p in PROBLEMS}
    source: dict[str, tuple[bool, str]] = {}  # name -> (a label?, the first file naming it)
    levels: dict[tuple, tuple] = {}  # (problem, name) -> ((noise, flip), the first file with it): one level each
    for arg in paths:
        label, path = _labelled(arg)
        try:
            recs = json.loads(Path(path).read_text())
            if not isinstance(recs, list) or not recs:
                raise ValueError("expected a non-empty list of runs")
            for rec in recs:
                missing = [k for k in _RECORD_KEYS if k not in rec]
                if missing:
                    raise KeyError(f"a run without {', '.join(missing)}")
                if rec["problem"] not in names:
                    raise KeyError(f"unknown problem {rec['problem']!r}")
            methods = {rec["method"] for rec in recs}
            if label is not None and len(methods) > 1:
                raise ValueError(f"label {label!r} given to a file of {len(methods)} methods ({', '.join(sorted(methods))}); "
                                 "label a file of one method")
            here = (label is not None, path)
            for m in ({label} if label is not None else methods):  # unlabelled files of one method merge
                first = source.setdefault(m, here)
                if first != here and (here[0] or first[0]):
                    raise ValueError(f"{m!r} names runs of {first[1]} too; give another label")
            for rec in recs:
                key = (rec["problem"], label or rec["method"])
                level = levels.setdefault(key, (_level(rec), path))
                if level[0] != _level(rec):
                    raise ValueError(f"{key[1]!r} on {key[0]} has runs at (noise, flip) {level[0]} in {level[1]} and "
                                     f"{_level(rec)} here; give one file a label (LABEL=FILE)")
                runs.setdefault(key, {})[rec["start"]] = rec
        except (OSError, ValueError, TypeError, KeyError) as exc:
            print(f"safe_bo_suite: cannot read runs from {path} ({type(exc).__name__}: {exc}); "
                  "give files written by --json", file=sys.stderr)
            raise SystemExit(2) from None
    return runs


_RECORD_KEYS = ("problem", "method", "start", "found", "fail", "beyond", "trials", "ms")  # files before issue 32 too


def _level(rec: dict) -> tuple[float, float]:
    """A saved run's (noise, flip); (0, 0) for a run saved before they were."""
    return float(rec.get("noise", 0.0)), float(rec.get("flip", 0.0))


def summarize(records) -> dict:
    """n, found (count and rate), failures per run, farthest failure, trials per run and ms per iteration of
    some runs; and their TRUE scores: ``within5`` and ``unsafe_best`` (counts), ``true_fail`` (per run),
    each None when a run saved before them lacks it, and ``errors`` (runs that raised)."""
    recs = list(records)
    n = len(recs)
    found = sum(bool(r["found"]) for r in recs)
    have = {k: all(k in r for r in recs) for k in ("within5", "true_fail", "unsafe_best")}
    return {"n": n, "found": found, "rate": found / n, "fail": float(np.mean([r["fail"] for r in recs])),
            "beyond": _largest([r["beyond"] for r in recs]), "trials": float(np.mean([r["trials"] for r in recs])),
            "ms": float(np.mean([r["ms"] for r in recs])),
            "within5": sum(bool(r["within5"]) for r in recs) if have["within5"] else None,
            "true_fail": float(np.mean([r["true_fail"] for r in recs])) if have["true_fail"] else None,
            "unsafe_best": sum(bool(r["unsafe_best"]) for r in recs) if have["unsafe_best"] else None,
            "errors": sum(bool(r.get("error")) for r in recs)}


def _largest(values) -> float:
    """The largest of ``values`` that were measured (NaN: not measured); NaN if none was."""
    v = np.asarray(values, dtype=float)
    return float(np.max(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")


def _print_head(head: list[str], markdown: bool, title: str) -> None:
    """A report's header: a Markdown table head, or the plain-text title."""
    if markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
    else:
        print(title)


def _print_cells(cells: list[str], markdown: bool) -> None:
    print("| " + " | ".join(cells) + " |" if markdown else "  ".join(c for c in cells if c))


def print_table(paths, budget: int = 40, markdown: bool = False) -> None:
    """The table of saved runs (``--json`` files, merged; a start saved twice counts once, the last)."""
    runs = load_runs(paths)
    order = {p.name: k for k, p in enumerate(PROBLEMS)}
    by_name = {p.name: p for p in PROBLEMS}
    levels = sorted({_level(r) for recs in runs.values() for r in recs.values()})
    true_scores = levels != [(0.0, 0.0)]  # some runs were noisy: show the TRUE scores
    heads = ["problem", "set", "method", "found", "failures", "beyond", "trials"]
    _print_head(heads + (_TRUE_HEADS if true_scores else []) + ["ms/it"], markdown,
                _table_title(budget, levels if true_scores else None))
    methods = ["CORL", *PEERS]
    rank = {m: k for k, m in enumerate(methods)}
    for prob, name in sorted(runs, key=lambda k: (order.get(k[0], len(order)), rank.get(k[1], len(rank)), k[1])):
        row = _row(by_name[prob], name, list(runs[(prob, name)].values()), true_scores)
        print("| " + " | ".join(row.split()) + " |" if markdown else row)


def verdict(runs: dict, method: str = "CORL") -> list[dict]:
    """Per problem with runs of ``method`` and of a peer: the issue's two must-show comparisons.

    ``finds``: ``method`` finds the optimum at least as often (as a rate: starts may differ) as
    the best-finding peer. ``fails_less``: it fails less often per run than every peer that finds
    the optimum at least as often as it does (a peer that rarely leaves the start fails little and
    finds little), or None when no peer finds it as often (nothing to compare with);
    ``fails_less_all`` compares with every peer.
    """
    out = []
    for p in PROBLEMS:
        if (p.name, method) not in runs:
            continue
        me = summarize(runs[(p.name, method)].values())
        peers = {m: summarize(r.values()) for (name, m), r in runs.items() if name == p.name and m != method}
        if not peers:
            continue
        best = max(peers, key=lambda m: (peers[m]["rate"], -peers[m]["fail"]))
        fewest = min(peers, key=lambda m: (peers[m]["fail"], -peers[m]["rate"]))
        finders = [m for m in peers if peers[m]["rate"] >= me["rate"]]
        out.append({"problem": p.name, "set": p.role, "me": me, "peers": peers, "best": best, "fewest": fewest,
                    "finds": me["rate"] >= peers[best]["rate"],
                    "fails_less": all(me["fail"] < peers[m]["fail"] for m in finders) if finders else None,
                    "fails_less_all": all(me["fail"] < q["fail"] for q in peers.values())})
    return out


def print_verdict(paths, budget: int = 40, markdown: bool = False, method: str = "CORL") -> None:
    """CORL beside the best-finding and the least-failing peer per problem, and the counts."""
    rows = verdict(load_runs(paths), method)
    yes = {True: "yes", False: "no", None: "n/a"}
    head = ["problem", "set", f"{method} found", "failures", "beyond", "best peer at finding",
            "fewest failures among peers", "finds as often", "fails less"]
    _print_head(head, markdown, f"Safe BO suite, {budget} trials: {method} beside the peers "
                "(found = within 2 % of the return range)")
    for v in rows:
        me, b, f = v["me"], v["peers"][v["best"]], v["peers"][v["fewest"]]
        cells = [v["problem"], v["set"], f"{me['found']}/{me['n']}", f"{me['fail']:.1f}", f"{me['beyond']:.3f}",
                 f"{v['best']} {b['found']}/{b['n']}, {b['fail']:.1f} failures",
                 f"{v['fewest']} {f['fail']:.1f} ({f['found']}/{f['n']} found)", yes[v["finds"]], yes[v["fails_less"]]]
        _print_cells(cells, markdown)
    n = len(rows)
    alone = sum(v["fails_less"] is None for v in rows)
    print(f"\n{method} finds the optimum at least as often as the best peer on {sum(v['finds'] for v in rows)} "
          f"of {n} problems. It fails less often than every peer that finds it as often on "
          f"{sum(v['fails_less'] is True for v in rows)} of the {n - alone} where some peer does "
          f"(n/a: no peer finds it as often on {alone}), and than every peer on "
          f"{sum(v['fails_less_all'] for v in rows)} of {n}.")


def print_compare(before: str, after: str, markdown: bool = False, method: str = "CORL") -> None:
    """``method``'s runs in two ``--json`` files per problem: found, failures, beyond, trials, before -> after."""
    a, b = load_runs([before]), load_runs([after])
    _print_head(["problem", "set", "found", "failures", "beyond", "trials"], markdown, f"{method}: {before} -> {after}")
    tot = {"found": [0, 0], "n": [0, 0], "fail": [[], []]}
    for p in PROBLEMS:
        if (p.name, method) not in a or (p.name, method) not in b:
            continue
        x, y = summarize(a[(p.name, method)].values()), summarize(b[(p.name, method)].values())
        cells = [p.name, p.role, f"{x['found']}/{x['n']} → {y['found']}/{y['n']}", f"{x['fail']:.1f} → {y['fail']:.1f}",
                 f"{x['beyond']:.3f} → {y['beyond']:.3f}", f"{x['trials']:.1f} → {y['trials']:.1f}"]
        _print_cells(cells, markdown)
        for k, s in enumerate((x, y)):
            tot["found"][k] += s["found"]
            tot["n"][k] += s["n"]
            tot["fail"][k].append(s["fail"])
    if tot["fail"][0]:
        cells = [f"all {len(tot['fail'][0])}", "", f"{tot['found'][0]}/{tot['n'][0]} → {tot['found'][1]}/{tot['n'][1]}",
                 f"{np.mean(tot['fail'][0]):.2f} → {np.mean(tot['fail'][1]):.2f} (mean per problem)", "", ""]
        _print_cells(cells, markdown)


def trade_off(runs: dict) -> tuple[list[str], dict]:
    """The problems every method ran, and per method :func:`summarize` over them (none if no problem is shared)."""
    methods = sorted({m for _, m in runs})
    shared = [p.name for p in PROBLEMS if all((p.name, m) in runs for m in methods)]
    if not shared:
        return shared, {}
    return shared, {m: summarize(r for name in shared for r in runs[(name, m)].values()) for m in methods}


def plot_trade_off(paths, out: str, budget: int = 40, markdown: bool = False) -> None:
    """Optima found against failures per run, one point per method or labelled file (``--trade-off``)."""
    shared, points = trade_off(load_runs(paths))
    if not shared:
        print("safe_bo_suite: no problem was run by every method given; nothing to plot", file=sys.stderr)
        raise SystemExit(2)
    order = sorted(points, key=lambda m: points[m]["fail"])
    _print_head(["method", "found", "failures per run", "beyond (max)", "trials per run"], markdown,
                f"Safe BO suite, {budget} trials, the {len(shared)} problems every method ran")
    for m in order:
        s = points[m]
        _print_cells([m, f"{s['found']}/{s['n']}", f"{s['fail']:.2f}", f"{s['beyond']:.3f}", f"{s['trials']:.1f}"],
                     markdown)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    colours = itertools.cycle(plt.get_cmap("tab10" if len(order) <= 10 else "tab20").colors)
    for m in order:
        s = points[m]
        marker = "s" if m in PEERS else ("*" if m == "CORL" else "o")
        ax.scatter(s["fail"], 100.0 * s["rate"], s=160 if m == "CORL" else 48, marker=marker,
                   color="black" if m == "CORL" else next(colours),
                   zorder=3, label=f"{m}: {s['found']}/{s['n']} found, {s['fail']:.2f} failures")
    ax.legend(fontsize=7.5, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    lo, hi = min(s["fail"] for s in points.values()), max(s["fail"] for s in points.values())
    if lo > 0:  # a log axis spreads the safe methods apart; a method that never fails needs a linear one
        ax.set_xscale("log")
        ticks = [v for v in (0.1, 0.2, 0.5, 1, 2, 3, 5, 10, 20, 30, 50) if lo / 1.5 <= v <= hi * 1.5]
        ax.set_xticks(ticks, [f"{v:g}" for v in ticks])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_xlabel("failures per run (mean" + (", log scale)" if lo > 0 else ")"))
    ax.set_ylabel("runs that found the optimum (%)")
    ax.set_title(f"{len(shared)} problems x {points[order[0]]['n'] // len(shared)} starts, {budget} trials: "
                 "up and to the left is better", fontsize=9)
    ax.grid(alpha=0.3)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    plt.close(fig)
    print(f"\nwritten: {out}")


_TRUE_HEADS = ["within 5 %", "true fail/run", "unsafe best", "errors"]  # the columns of the TRUE scores


def _table_title(budget: int, levels=None) -> str:
    """The plain-text table's title and column heads (rows: :func:`_row`).

    ``levels``: the (noise, flip) levels of the runs shown, for a table with the TRUE scores; None: without them.
    """
    if levels is None:
        return (f"Safe BO suite: {budget} trials, start told first; found = within 2 % of the return range\n"
                f"{'problem':<14} {'set':<9} {'method':<13} {'found':>7} {'fail':>6} {'beyond':>7} {'trials':>7} "
                f"{'ms/it':>8}\n" + "-" * 78)
    noisy = "; ".join(f"noise {n:g} x the return range, flip {q:g}" for n, q in levels)
    return (f"Safe BO suite: {budget} trials, start told first; {noisy}\nscored on the TRUE R and S: found = a "
            "truly safe trial within 2 % of the return range, within5 = the reported best truly safe and within 5 %\n"
            f"{'problem':<14} {'set':<9} {'method':<13} {'found':>7} {'fail':>6} {'beyond':>7} {'trials':>7} "
            f"{'within5':>7} {'true fail/run':>13} {'unsafe best':>11} {'errors':>6} {'ms/it':>8}\n" + "-" * 120)


def _row(p, name, runs, true_scores: bool = False) -> str:
    """One row of the table: :func:`summarize` of ``runs``, with the TRUE scores' columns when ``true_scores``."""
    s = summarize(runs)
    row = (f"{p.name:<14} {p.role:<9} {name:<13} {s['found']:>3}/{s['n']:<3} {s['fail']:>6.1f} {s['beyond']:>7.3f} "
           f"{s['trials']:>7.1f}")
    if true_scores:  # "-": runs saved before the TRUE scores were
        within5, unsafe = (_share(s[k], s["n"]) for k in ("within5", "unsafe_best"))
        true_fail = "-" if s["true_fail"] is None else f"{s['true_fail']:.1f}"
        row += f" {within5:>7} {true_fail:>13} {unsafe:>11} {s['errors']:>6}"
    return row + f" {s['ms']:>8.1f}"


def _share(k: int | None, n: int) -> str:
    return "-" if k is None else f"{k:>3}/{n:<3}"


if __name__ == "__main__":
    main()
