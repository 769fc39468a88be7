"""What the run store costs per trial: ``add_proposal`` + ``add_outcome``, each committed to disk.

Usage: ``python benchmarks/store_overhead.py [--trials 300] [--dir PATH]``

``--dir`` should be on the disk the real stores live on: the cost is dominated by the two fsyncs
per trial (``synchronous=FULL``), so a RAM disk or a network disk gives a different answer.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from corl.problem import Outcome, Proposal
from corl.store import RunStore

TARGET_MS = 2.0


def time_trials(folder: Path, n: int, trials: int, seed: int = 0) -> np.ndarray:
    """Milliseconds per trial (proposal + outcome), (trials,), for ``w`` of size ``n``."""
    rng = np.random.default_rng(seed)
    costs = np.empty(trials)
    with RunStore(folder / f"bench_{n}.corl") as store:
        run = store.create_run(task="benchmark", method="none", seed=seed, config={"n": n})
        for k in range(trials):
            proposal = Proposal(k, rng.normal(size=n), rng.normal(size=2), "reinforcement", k // 10)
            outcome = Outcome(True, float(rng.normal()), {"angle": float(rng.uniform())})
            start = time.perf_counter()
            store.add_proposal(run, proposal)
            store.add_outcome(run, k, outcome)
            costs[k] = 1e3 * (time.perf_counter() - start)
    return costs


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--dir", type=Path, default=None, help="folder for the temporary stores")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.dir) as folder:
        print(f"run store overhead, {args.trials} trials per row, stores in {folder}")
        print(f"{'n (size of w)':>14} {'median ms':>10} {'p95 ms':>8} {'max ms':>8} {'target':>10}")
        for n in (1200, 2):
            costs = time_trials(Path(folder), n, args.trials)
            median, p95 = np.percentile(costs, [50, 95])
            verdict = "ok" if p95 < TARGET_MS else "MISSED"
            print(f"{n:>14} {median:>10.3f} {p95:>8.3f} {costs.max():>8.3f} {'< 2 ms':>10} {verdict}")


if __name__ == "__main__":
    main()
