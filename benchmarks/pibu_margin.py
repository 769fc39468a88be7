"""Where does the paper's max-distance margin come from? CORL+PIBU under classifier variants.

    python benchmarks/pibu_margin.py [--starts 40] [--jobs 2]

PIBU walks towards the boundary in steps set by where the classifier's band (p = 0.45..0.55)
sits beyond the outermost success; that offset scales with the classifier's length scale l_S, and
a failure overshoots the true boundary by up to one such step. Rows: the paper's hyperparameters,
l_S / sqrt(2) (Eq. 16 written without the 1/2), l_S / 2, and a weaker prior mean.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from corl.experiments.synthetic import aggregate, sweep  # noqa: E402
from corl.settings import PAPER_SYNTHETIC, SYNTHETIC_CLASSIFIER  # noqa: E402

VARIANTS = {
    "paper: l_S=0.4, c=-7": SYNTHETIC_CLASSIFIER,
    "l_S=0.283 (no 1/2)": replace(SYNTHETIC_CLASSIFIER, lengthscale=0.4 / 2**0.5),
    "l_S=0.2": replace(SYNTHETIC_CLASSIFIER, lengthscale=0.2),
    "c=-3": replace(SYNTHETIC_CLASSIFIER, prior_mean=-3.0),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--starts", type=int, default=40)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print(f"CORL+PIBU, {args.starts} starts; paper: 100/100, failures 2.04 ± 0.19, max dist 0.10 ± 0.04")
    print(f"{'classifier':<24} {'found':>7} {'failures':>13} {'max dist':>15} {'theta trials':>13}")
    for name, clf in VARIANTS.items():
        rows = sweep(["CORL+PIBU"], args.starts, args.seed, jobs=args.jobs, settings=replace(PAPER_SYNTHETIC, classifier=clf))
        t = aggregate(rows, ["CORL+PIBU"])["CORL+PIBU"]
        print(f"{name:<24} {t['found']:>3}/{t['starts']:<3} {t['failures_mean']:>6.2f} ± {t['failures_std']:<4.2f} "
              f"{t['max_dist_mean']:>7.3f} ± {t['max_dist_std']:<5.3f} {t['theta_trials_mean']:>13.1f}")


if __name__ == "__main__":
    main()
