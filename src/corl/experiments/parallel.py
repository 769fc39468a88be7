"""One robot against K (``corl bench parallel``): the same learning, each trial taking S seconds of robot time.

Each run is a stored run (``OUT/robots-K.corl``) driven by :func:`corl.fleet.run_fleet`: a worker
process per trial that rolls the task out and then sleeps S seconds (the time a real robot or a
slow simulator spends); the learner keeps as many trials out as it hands out, up to K, and tells
each outcome as its process ends. ``OUT/parallel.json`` holds ``{"runs": {"1": {...}, "K": {...}}}``
with ``wall_s``, ``trials``, ``failures``, ``final_return`` (the learner's best), ``out_at_once``
(how many trials were out, counted at each tell) and the best return against wall time;
``OUT/parallel.png`` plots the latter.
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

__all__ = ["parallel_run", "parallel_bench", "plot_parallel"]


def parallel_run(task_spec: str, robots: int, seconds: float, seed: int, store_path: Path, *,
                 overrides: dict | None = None, backend: str = "local", address: str | None = None,
                 progress=None) -> dict:
    """One stored run of CORL on ``task_spec`` with ``robots`` robots; what parallel.json records of it."""
    from corl.fleet import run_fleet
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.registry import load_task

    task = load_task(task_spec, seed=seed)
    session = StoredRun.new(task, task_spec=task_spec, method="CORL", seed=seed, corl_overrides=overrides,
                            robots=robots)
    curve, out, t0 = [], Counter(), time.perf_counter()

    def tick(p, o):
        out[len(session.pending) + 1] += 1  # this one and those still out
        best = session.best
        curve.append((time.perf_counter() - t0, None if best is None else float(best.return_)))
        if progress is not None:
            progress(robots, p, o, session)

    with RunStore(store_path) as db:
        session.attach(db)
        run_fleet(session, task, robots=robots, backend=backend, trial_seconds=seconds, callback=tick,
                  task_spec=task_spec, seed=seed, address=address)
    history = session.history
    return {"wall_s": time.perf_counter() - t0, "trials": len(history),
            "failures": sum(not o.success for _, o in history),
            "final_return": None if session.best is None else float(session.best.return_),
            "stop_reason": getattr(getattr(session.learner, "stop_reason", None), "value", None),
            "out_at_once": {str(k): v for k, v in sorted(out.items())}, "store": str(store_path),
            "run_id": session.run_id, "curve": curve}


def parallel_bench(task_spec: str, robots: int, seconds: float, seed: int, out: Path, *,
                   overrides: dict | None = None, backend: str = "local", address: str | None = None,
                   progress=None) -> dict:
    """:func:`parallel_run` with one robot, then with ``robots``; the payload of parallel.json."""
    runs = {str(k): parallel_run(task_spec, k, seconds, seed, out / f"robots-{k}.corl", overrides=overrides,
                                 backend=backend, address=address, progress=progress)
            for k in dict.fromkeys((1, robots))}
    from corl.versions import library_versions

    one, many = runs["1"], runs[str(robots)]
    return {"versions": library_versions(), "task": task_spec, "robots": robots, "trial_seconds": seconds, "seed": seed, "backend": backend,
            "corl_overrides": overrides or {}, "wall_ratio": many["wall_s"] / one["wall_s"], "runs": runs}


def plot_parallel(payload: dict, path: Path) -> Path:
    """The best return against wall time of each run of ``payload`` (parallel.json), written to ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    for k, r in payload["runs"].items():
        points = [(t, b) for t, b in r["curve"] if b is not None]
        ax.step([t for t, _ in points], [b for _, b in points], where="post",
                label=f"{k} robot{'' if k == '1' else 's'}: {r['trials']} trials, {r['failures']} "
                      f"failure{'' if r['failures'] == 1 else 's'}")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("best return (the learner's)")
    ax.set_title(f"{payload['task']}: {payload['trial_seconds']:g} s per trial", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
