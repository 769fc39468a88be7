"""Speed of one PIBU iteration: fit g_R and g_S, maximise Eq. 17 (issue targets beside each row).

    python benchmarks/pibu_speed.py [--repeats 30]

Data: points uniform in the box, labelled by the synthetic safe set, returns R(theta) (1-D) or
R(theta) - J(w) (2-D, the baseline over w). Paper hyperparameters (l=0.4, sf=10, sigma=0.11, c=-7).
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from corl.optimizers.bo import PIBUOptimizer  # noqa: E402
from corl.problem import Bounds, Outcome  # noqa: E402
from corl.tasks.synthetic import SyntheticTask, return_of  # noqa: E402


def one_iteration_ms(m: int, n_points: int, repeats: int, seed: int = 0) -> tuple[float, float]:
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
    rows = [("1-D, 50 points", 1, 50, 10.0), ("2-D, 100 points", 2, 100, 50.0)]
    print(f"{'case':<18} {'median ms':>10} {'p95 ms':>8} {'target ms':>10}  verdict")
    for label, m, n, target in rows:
        med, p95 = one_iteration_ms(m, n, args.repeats)
        verdict = "ok" if med < target else "MISSED"
        print(f"{label:<18} {med:>10.2f} {p95:>8.2f} {'< ' + format(target, 'g'):>10}  {verdict}")


if __name__ == "__main__":
    main()
