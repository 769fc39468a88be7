"""One robot against K: the same learning (corl.parallel.ParallelCORL), each trial taking S seconds of robot time.

Each trial runs in a worker process (concurrent.futures, fork): ``task.rollout(w)`` and then
``time.sleep(S)``, the time a real robot or a slow simulator spends. The learner keeps as many trials
out as it hands out (up to K) and tells each outcome as soon as its process ends, filling up again
after every tell. Writes ``OUT/parallel.json`` ``{"runs": {"1": {...}, "K": {...}}}`` with ``wall_s``,
``trials``, ``failures``, ``final_return`` and the best return against wall time, and
``OUT/parallel.png``.

    python benchmarks/parallel_trials.py --robots 4 --trial-seconds 0.5 --seed 0 --out /tmp/par \
        [--rollout-every-step | --no-rollout-every-step]
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from pathlib import Path


def _rollout(task, w, seconds: float):
    outcome = task.rollout(w)
    time.sleep(seconds)
    return outcome


def run(task_name: str, robots: int, seconds: float, seed: int, every_step: bool) -> dict:
    from corl.methods import make_method
    from corl.parallel import ParallelCORL
    from corl.session import _settings
    from corl.tasks.registry import load_task

    task = load_task(task_name, seed=seed)
    corl = make_method("CORL", task, seed=seed, settings=_settings(task, {"rollout_every_step": every_step}))
    learner = ParallelCORL(corl.task, corl.optimizer_factory, corl.config, seed=seed, robots=robots)
    curve, t0 = [], time.perf_counter()
    with ProcessPoolExecutor(max_workers=robots, mp_context=multiprocessing.get_context("fork")) as pool:
        running = {}
        while not learner.done:
            while (proposal := learner.try_ask()) is not None:
                running[pool.submit(_rollout, learner.task, proposal.w, seconds)] = proposal.index
            if not running:
                break  # Algorithm 1 ended when asked for its next trial
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in sorted(finished, key=running.get):
                learner.tell(future.result(), running.pop(future))
                best = learner.best
                curve.append((time.perf_counter() - t0, None if best is None else best.return_))
                while (proposal := learner.try_ask()) is not None:  # fill up after every tell
                    running[pool.submit(_rollout, learner.task, proposal.w, seconds)] = proposal.index
    history = learner.history
    return {"wall_s": time.perf_counter() - t0, "trials": len(history),
            "failures": sum(not o.success for _, o in history),
            "final_return": None if learner.best is None else learner.best.return_,
            "stop_reason": None if learner.stop_reason is None else learner.stop_reason.value,
            "curve": curve}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="synthetic")
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--trial-seconds", type=float, default=0.5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--rollout-every-step", action=argparse.BooleanOptionalAction, default=False)
    args = parser.parse_args(argv)
    if args.robots < 1 or not args.trial_seconds >= 0:
        print("--robots must be >= 1 and --trial-seconds >= 0", file=sys.stderr)
        return 2
    runs = {str(k): run(args.task, k, args.trial_seconds, args.seed, args.rollout_every_step)
            for k in dict.fromkeys((1, args.robots))}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "parallel.json").write_text(json.dumps({"task": args.task, "trial_seconds": args.trial_seconds,
                                                        "seed": args.seed, "runs": runs}, indent=1))
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    for k, r in runs.items():
        ax.step([t for t, b in r["curve"] if b is not None], [b for _, b in r["curve"] if b is not None],
                where="post", label=f"{k} robot{'s' if k != '1' else ''}")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("best return")
    ax.legend()
    fig.tight_layout()
    fig.savefig(args.out / "parallel.png", dpi=120)
    for k, r in runs.items():
        print(f"K={k}: wall {r['wall_s']:.1f} s, {r['trials']} trials, {r['failures']} failures, "
              f"final return {r['final_return']:.6f} ({r['stop_reason']})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
