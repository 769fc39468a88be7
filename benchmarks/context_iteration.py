"""Cost of one contextual black-box iteration against one plain iteration at the same amount of data.

    python benchmarks/context_iteration.py [--repeats 5]

One iteration is what a learner pays per trial in step 2 of Algorithm 1: fit g_R and g_S (MAP
hyperparameters, warm-started as in a run), maximise SEIB, apply the stopping rules
(:class:`corl.optimizers.safe.SafeBOOptimizer`, the ``CORL`` method). Both arms see the same d
trials of the synthetic family (``corl.tasks.synthetic.ContextualSyntheticTask``: theta in
[-pi, pi], R and S shifted by 0.5 c):

* **plain**: d trials in one scene, GPs over theta (m = 1);
* **contextual**: d trials over 8 scenes (the current one holds d / 8), GPs over (theta, c)
  (m + k = 2) read at the current scene (:class:`corl.contexts.ContextualModels`).

Reported: median ms per iteration over the repeats (a fresh optimizer each, the models warm from
one earlier fit like in a run) and their ratio. The library versions are printed with the table.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from corl.contexts import ContextData, ContextualModels  # noqa: E402
from corl.optimizers.safe import SafeBOOptimizer  # noqa: E402
from corl.problem import Outcome  # noqa: E402
from corl.tasks.synthetic import CONTEXT_BOUNDS, SAFE_HIGH, SAFE_LOW, ContextualSyntheticTask, return_of  # noqa: E402
from corl.versions import library_versions  # noqa: E402

BOX = ContextualSyntheticTask.theta_bounds
SCENES = 8


def outcome(theta: float, c: float) -> Outcome:
    u = theta - 0.5 * c
    ok = SAFE_LOW < u < SAFE_HIGH
    return Outcome(ok, return_of(u) if ok else None)


def trials(d: int, seed: int):
    """d thetas near each scene's optimum (where a learner samples), in SCENES scenes."""
    rng = np.random.default_rng(seed)
    contexts = CONTEXT_BOUNDS.from_unit((np.arange(SCENES) + 0.5)[:, None] / SCENES)
    c = np.repeat(contexts, int(np.ceil(d / SCENES)), axis=0)[:d]
    theta = np.clip(0.5 * c + rng.normal(0.0, 0.9, size=(d, 1)), BOX.lower, BOX.upper)
    return theta, c


def iteration_ms(d: int, contextual: bool, seed: int) -> float:
    theta, c = trials(d, seed)
    here = c[:, 0] == c[-1, 0]
    opt = SafeBOOptimizer(BOX, max_evals=10**6, seed=seed)
    if contextual:
        others = [outcome(t, s) for t, s in zip(theta[~here, 0], c[~here, 0])]
        prior = ContextData(theta[~here], c[~here], [o.success for o in others],
                            [np.nan if o.return_ is None else o.return_ for o in others])
        opt.models = ContextualModels(BOX, CONTEXT_BOUNDS, prior, c[-1])
        mine = theta[here]
        scene = c[-1, 0]
    else:
        mine, scene = theta, 0.0
    points = [(t, outcome(t, scene)) for t in mine[:, 0]]
    if not any(o.success for _, o in points):
        points.append((0.5 * scene, outcome(0.5 * scene, scene)))
    for t, o in points[:-1]:
        opt.tell([t], o)
    opt.done  # one earlier fit: the next one is warm, as in a run
    t, o = points[-1]
    opt.tell([t], o)
    t0 = time.perf_counter()
    opt.done
    return 1e3 * (time.perf_counter() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"one CORL (SEIB) iteration: plain (GPs over theta, one scene) vs contextual (GPs over (theta, c), "
          f"{SCENES} scenes), same number of trials d; median of {args.repeats}")
    print(f"{'d':>5s} {'plain ms':>10s} {'contextual ms':>14s} {'ratio':>7s}")
    for d in (16, 32, 64, 128, 256):
        plain = float(np.median([iteration_ms(d, False, s) for s in range(args.repeats)]))
        ctx = float(np.median([iteration_ms(d, True, s) for s in range(args.repeats)]))
        print(f"{d:5d} {plain:10.1f} {ctx:14.1f} {ctx / plain:7.2f}")
    v = library_versions()
    print("versions: " + ", ".join(f"{k} {v[k]}" for k in ("python", "numpy", "scipy") if k in v))


if __name__ == "__main__":
    main()
