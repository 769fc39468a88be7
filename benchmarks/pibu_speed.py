"""Speed of one PIBU iteration: fit g_R and g_S, maximise Eq. 17 (issue targets beside each row).

    python benchmarks/pibu_speed.py [--repeats 30]

Data: points uniform in the box, labelled by the synthetic safe set, returns R(theta) (1-D) or
R(theta) - J(w) (2-D, the baseline over w). Paper hyperparameters (l=0.4, sf=10, sigma=0.11, c=-7).
3-D and 4-D: points uniform in the unit box, safe inside the ball |theta - 0.5| < 0.35, return
1 - |theta - 0.6|^2, length scales a tenth of the box (``OptimizerSettings.for_box``). A second
table compares the m >= 3 maximiser with the one before boundary seeding (2,048 Sobol points):
ms per maximisation and the acquisition value each finds (mean over the repeats, one seed each).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from corl.acquisition import MaximizerConfig, maximize  # noqa: E402
from corl.optimizers.bo import PIBUOptimizer  # noqa: E402
from corl.optimizers.registry import OptimizerSettings  # noqa: E402
from corl.problem import Bounds, Outcome  # noqa: E402

OLD_ND = MaximizerConfig(samples_nd=2048, boundary_pairs=0)  # the m >= 3 maximiser before boundary seeding
from corl.tasks.synthetic import SyntheticTask, return_of  # noqa: E402


def ball_optimizer(m: int, n_points: int, seed: int = 0) -> PIBUOptimizer:
    """PIBU on the m-D ball problem with ``n_points`` uniform points told."""
    rng = np.random.default_rng(seed)
    box = Bounds(np.zeros(m), np.ones(m))
    opt = PIBUOptimizer(box, OptimizerSettings.for_box(box).bo(), max_evals=10**6, seed=seed)
    for x in rng.uniform(0.0, 1.0, size=(n_points, m)):
        ok = bool(np.linalg.norm(x - 0.5) < 0.35)
        opt.tell(x, Outcome(ok, 1.0 - float(np.sum((x - 0.6) ** 2)) if ok else None))
    return opt


def maximiser_compare(m: int, n_points: int, repeats: int) -> dict:
    """ms per maximisation and the value found, new maximiser vs the one before seeding."""
    opt = ball_optimizer(m, n_points)
    opt._propose()
    acq = opt.last_acquisition
    out = {}
    for name, cfg in (("new", MaximizerConfig()), ("old", OLD_ND)):
        times, values = [], []
        for seed in range(repeats):
            t0 = time.perf_counter()
            _, v = maximize(acq, opt.bounds, rng=np.random.default_rng(seed), config=cfg, extra=opt.X_)
            times.append(time.perf_counter() - t0)
            values.append(v)
        out[name] = (1e3 * float(np.median(times)), float(np.mean(values)), float(np.min(values)))
    return out


def one_iteration_ms(m: int, n_points: int, repeats: int, seed: int = 0) -> tuple[float, float]:
    if m >= 3:
        opt = ball_optimizer(m, n_points, seed)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            opt._propose()
            times.append(time.perf_counter() - t0)
        t = np.array(times) * 1e3
        return float(np.median(t)), float(np.percentile(t, 95))
    rng = np.random.default_rng(seed)
    task = SyntheticTask()
    bounds = task.theta_bounds if m == 1 else task.w_bounds
    X = rng.uniform(bounds.lower, bounds.upper, size=(n_points, m))
    opt = PIBUOptimizer(bounds, max_evals=10**6, seed=seed)
    for x in X:
        if m == 1:
            theta = float(x[0])
            ok = -1.5 < theta < 2.5
            opt.tell(x, Outcome(ok, return_of(theta) if ok else None))
        else:
            out = task.rollout(x)
            J = float(task.cost_residuals(x)[0][0] ** 2)
            opt.tell(x, Outcome(out.success, out.return_ - J if out.success else None))
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        opt._propose()  # fit both GPs, build Eq. 17, maximise it, apply the stopping rule
        times.append(time.perf_counter() - t0)
    t = np.array(times) * 1e3
    return float(np.median(t)), float(np.percentile(t, 95))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=30)
    args = ap.parse_args()
    rows = [("1-D, 50 points", 1, 50, 10.0), ("2-D, 100 points", 2, 100, 50.0),
            ("3-D, 100 points", 3, 100, 100.0), ("4-D, 100 points", 4, 100, 100.0)]
    print(f"{'case':<18} {'median ms':>10} {'p95 ms':>8} {'target ms':>10}  verdict")
    for label, m, n, target in rows:
        med, p95 = one_iteration_ms(m, n, args.repeats)
        verdict = "ok" if med < target else "MISSED"
        print(f"{label:<18} {med:>10.2f} {p95:>8.2f} {'< ' + format(target, 'g'):>10}  {verdict}")
    print()
    print(f"{'maximiser':<18} {'new ms':>8} {'old ms':>8} {'new value':>10} {'old value':>10} {'new min':>8} {'old min':>8}")
    for m in (3, 4):
        for n in (30, 100):
            c = maximiser_compare(m, n, args.repeats)
            print(f"{f'{m}-D, {n} points':<18} {c['new'][0]:>8.2f} {c['old'][0]:>8.2f} {c['new'][1]:>10.4f} "
                  f"{c['old'][1]:>10.4f} {c['new'][2]:>8.4f} {c['old'][2]:>8.4f}")


if __name__ == "__main__":
    main()
