"""``corl bench contexts``: one skill across scenes against learning each scene from scratch.

Train on N contexts (the demonstration's own, then N - 1 spread over the box by a Latin
hypercube), every
run in one store (:mod:`corl.contexts`), in turn, each learning from the runs before it. Then, in
each of M held-out test contexts drawn from the box, side by side:

* **contextual**: the skill's policy, then learning in that scene (:class:`ContextualCORL`);
* **scratch**: the default method (CORL) from the scene's own demonstration, alone;
* **nearest**: the nearest training context's ``w*`` realised in the scene (Eq. 18 at its
  ``theta*``) and used as it is: one trial.

Each runs until it stops or ``budget`` trials. The ground truth of a test context is a sweep of
its theta box realised from the scene's demonstration after step 1 to convergence (the motion
every learner starts to optimise; what ``corl sweep`` does from that anchor); its best
return ``R_best`` defines the target ``R >= R_best - 0.05 |R_best|`` (95 % of it for a positive
return). Per method and test context: whether the first trial succeeded, the trials until the
target (the budget when never), the failures, and the final return (the best successful one)
over ``R_best``; ``failures_to_95`` counts the failures until the target. Test contexts run in
parallel workers, each reading the training store.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from corl.errors import InputError

__all__ = ["METHODS", "TARGET_FRACTION", "draw_contexts", "train", "evaluate_context", "summarise", "bench_contexts",
           "contexts_table", "plot_contexts"]

METHODS = ("contextual", "scratch", "nearest")
TARGET_FRACTION = 0.95  # a trial reaches the target at R >= R_best - (1 - TARGET_FRACTION) |R_best|
GRID_POINTS = 64  # sweep points per test context (spread over theta's dimensions)


def draw_contexts(bounds, count: int, rng: np.random.Generator, *, spread: bool = False) -> np.ndarray:
    """``count`` contexts uniform in the box, (count, k); ``spread``: a Latin hypercube (one per
    stratum of each coordinate), so that training contexts cover the box however few they are."""
    if not spread:
        return bounds.from_unit(rng.random((count, bounds.dim)))
    u = (np.argsort(rng.random((bounds.dim, count)), axis=1).T + rng.random((count, bounds.dim))) / max(count, 1)
    return bounds.from_unit(u)


def _task(spec: str, seed: int):
    from corl.experiments.sweep import TaskSpec

    return TaskSpec(spec, seed)()


def _stored_runs(store: Path) -> list:
    """The runs of ``store`` in the order they were created; none for a missing or empty file (a
    creation that was killed before its first commit)."""
    from corl.store import RunStore
    from corl.store.records import EmptyStoreError

    if not store.exists():
        return []
    try:
        with RunStore(store, create=False, readonly=True) as ro:
            return ro.runs()
    except EmptyStoreError:
        return []


def _row(c, history, best, start: str, seconds: float) -> dict:
    return {"context": [float(v) for v in c], "trials": len(history),
            "failures": sum(not o.success for _, o in history),
            "best_return": None if best is None else float(best.return_), "start": start or "demonstration",
            "seconds": seconds}


def train(spec: str, seed: int, contexts: np.ndarray, store: Path, progress=None) -> list[dict]:
    """Learn in each context in turn, every run in ``store``, each from the runs before it; one
    summary per run. Resumable: the i-th run of the store is context i; a finished one is kept, an
    unfinished one continued exactly (:meth:`StoredRun.open`), a missing one started."""
    from corl.session import StoredRun
    from corl.store import RunStatus, RunStore

    task = _task(spec, seed)
    rows = []
    for i, c in enumerate(contexts):
        t0 = time.perf_counter()
        existing = _stored_runs(store)
        with RunStore(store, create=False, readonly=True) if existing else nullcontext() as ro:
            if i < len(existing):
                info = existing[i]
                recorded = info.config.get("context")
                if recorded is None or not np.allclose(recorded, c, rtol=0.0, atol=1e-12):
                    raise InputError(f"run {info.id} of {store} was learned in context {recorded}, not {c.tolist()}: "
                                     "this store belongs to another study; choose another --out")
                run = StoredRun.open(ro, task, info.id)
            else:
                run = StoredRun.new(task, task_spec=spec, method="CORL", seed=seed, context=c, learned_from=ro)
        if i >= len(existing) or existing[i].status is not RunStatus.FINISHED:
            with RunStore(store) as db:
                run.attach(db)
                run.run(task.with_context(c))
        rows.append(_row(c, run.history, run.best, getattr(run.learner, "start_kind", ""), time.perf_counter() - t0))
        if progress is not None:
            progress("train", i + 1, len(contexts), rows[-1])
    return rows


def _grid(dim: int) -> tuple[int, ...]:
    side = max(3, int(round(GRID_POINTS ** (1.0 / dim))))
    return (side,) * dim


def _scores(outcomes, target: float, budget: int, best_swept: float) -> dict:
    """What one method did in one context, from its trials' outcomes (in order)."""
    reach = next((i + 1 for i, o in enumerate(outcomes) if o.success and o.return_ >= target), budget)
    before = outcomes[:reach]  # the trials until the target (all of them when it was never reached)
    returns = [o.return_ for o in outcomes if o.success]
    final = max(returns) if returns else None
    ratio = 0.0 if final is None else float(final / best_swept) if best_swept != 0 else float("nan")
    return {"trials": len(outcomes), "first_trial_success": bool(outcomes and outcomes[0].success),
            "trials_to_95": int(reach), "failures": sum(not o.success for o in outcomes),
            "failures_to_95": sum(not o.success for o in before),
            "final_return": final, "final_return_ratio": ratio}


def evaluate_context(spec: str, seed: int, store: str, context, budget: int, grid=None) -> dict:
    """The three methods and the sweep in one test context (runs in a worker)."""
    from corl.contexts import ContextualCORL, Skill
    from corl.experiments.sweep import _solver, evaluate_points
    from corl.loop import drive
    from corl.methods import make_method
    from corl.realise import feasible, motion_problem, realise
    from corl.trajectory.solver import solve

    task = _task(spec, seed)
    c = np.asarray(context, dtype=float)
    scene = task.with_context(c)
    t0 = time.perf_counter()
    # ground truth: the sweep of this scene from its own demonstration's motion at its best (Eq. 8 at
    # theta0 to convergence, no trial: R depends on the motion, and every learner optimises it)
    demo = scene.demonstration()
    solver = _solver(scene)
    best_motion = solve(motion_problem(scene, demo.theta), demo.w, config=solver)
    if feasible(best_motion, solver):
        demo = type(demo)(best_motion.w, demo.theta)
    bounds = scene.theta_bounds
    sizes = tuple(grid) if grid is not None else _grid(bounds.dim)
    axes = [np.linspace(lo, hi, g) for lo, hi, g in zip(bounds.lower, bounds.upper, sizes)]
    points = np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])
    success, _, returns = evaluate_points(scene, demo.w, demo.theta, points)
    if not np.any(success):
        raise InputError(f"no theta of the sweep succeeds in context {c.tolist()}; the ground truth is missing")
    best_swept = float(np.nanmax(returns))
    theta_swept = points[int(np.nanargmax(returns))]
    target = best_swept - (1.0 - TARGET_FRACTION) * abs(best_swept)
    t_sweep = time.perf_counter() - t0
    out = {"context": c.tolist(), "best_swept": best_swept, "theta_swept": theta_swept.tolist(),
           "target": target, "sweep_points": int(len(points)), "seconds": {"sweep": t_sweep}}

    skill = Skill.load(store, task)
    policy = skill.policy(c)
    out["policy"] = {"theta": policy.theta.tolist(), "p_success": policy.p_success, "R_mean": policy.R_mean,
                     "R_std": policy.R_std, "nearest": policy.nearest.tolist()}
    seen = {}
    learners = {"contextual": lambda: ContextualCORL(task, c, skill, seed=seed),
                "scratch": lambda: make_method("CORL", scene, seed=seed)}
    for name, build in learners.items():
        t0 = time.perf_counter()
        learner = build()
        drive(learner, scene, max_trials=budget)
        outcomes = [o for _, o in learner.history]
        out[name] = _scores(outcomes, target, budget, best_swept)
        seen[name] = outcomes
        best = learner.best
        out[name]["theta"] = None if best is None else np.asarray(best.theta).tolist()
        out["seconds"][name] = time.perf_counter() - t0
    # nearest: the nearest training context's w* realised here at its theta*, used as is
    t0 = time.perf_counter()
    anchor = skill.nearest(c)
    done = realise(scene, anchor.w, anchor.theta, anchor.theta, solver)
    if done.feasible:
        outcomes = [scene.rollout(done.w)]
    else:  # not realisable here: it cannot be run, a failure without a rollout
        from corl.problem import Outcome

        outcomes = [Outcome(False, None, {"unrealisable": True})]
    out["nearest"] = _scores(outcomes, target, budget, best_swept)
    seen["nearest"] = outcomes
    out["nearest"]["theta"] = anchor.theta.tolist()
    out["seconds"]["nearest"] = time.perf_counter() - t0
    # the best return known here: the sweep's or any method's; 95 % of it is the stricter target
    known = max([best_swept] + [o.return_ for rows in seen.values() for o in rows if o.success])
    out["best_known"] = known
    strict = known - (1.0 - TARGET_FRACTION) * abs(known)
    for name, rows in seen.items():
        out[name]["trials_to_95_known"] = next(
            (i + 1 for i, o in enumerate(rows) if o.success and o.return_ >= strict), budget)
        final = out[name]["final_return"]
        out[name]["final_return_known"] = 0.0 if final is None else float(final / known) if known else float("nan")
    return out


def summarise(per_context: list[dict]) -> dict:
    """Means over the test contexts, per method (the ``methods`` table of contexts.json)."""
    table = {}
    for name in METHODS:
        rows = [r[name] for r in per_context]
        table[name] = {"first_trial_success": float(np.mean([r["first_trial_success"] for r in rows])),
                       "trials_to_95": float(np.mean([r["trials_to_95"] for r in rows])),
                       "failures": float(np.mean([r["failures"] for r in rows])),
                       "failures_to_95": float(np.mean([r["failures_to_95"] for r in rows])),
                       "final_return_ratio": float(np.mean([r["final_return_ratio"] for r in rows])),
                       "trials_to_95_known": float(np.mean([r["trials_to_95_known"] for r in rows])),
                       "final_return_known": float(np.mean([r["final_return_known"] for r in rows])),
                       "trials": float(np.mean([r["trials"] for r in rows]))}
    return table


@dataclass(frozen=True)
class _Job:
    spec: str
    seed: int
    store: str
    budget: int

    def __call__(self, context):
        return evaluate_context(self.spec, self.seed, self.store, context, self.budget)


def bench_contexts(spec: str, *, train_count: int, test_count: int, seed: int, out: Path, budget: int = 40,
                   jobs: int = 1, progress=None) -> dict:
    """The whole study; writes ``out/train.corl`` (the skill) and returns the contexts.json payload.

    A ``train.corl`` already in ``out`` from the same study (task, seed, training contexts) is
    reused: its finished runs are kept and an unfinished one is resumed (:func:`train`)."""
    from joblib import Parallel, delayed

    from corl.contexts import context_task
    from corl.versions import library_versions

    task = context_task(_task(spec, seed))
    box = task.context_bounds
    rng = np.random.default_rng([seed, 22])
    spread = draw_contexts(box, train_count - 1, rng, spread=True)
    contexts = np.vstack([np.asarray(task.context, dtype=float)[None], spread])
    tests = draw_contexts(box, test_count, np.random.default_rng([seed, 22, 1]))
    store = Path(out) / "train.corl"
    t0 = time.perf_counter()
    trained = train(spec, seed, contexts, store, progress)
    t_train = time.perf_counter() - t0
    job = _Job(spec, seed, str(store), budget)
    per_context = []
    with Parallel(n_jobs=jobs, return_as="generator") as parallel:
        for i, row in enumerate(parallel(delayed(job)(c) for c in tests)):
            per_context.append(row)
            if progress is not None:
                progress("test", i + 1, len(tests), row)
    return {"task": spec, "seed": seed, "theta_labels": list(getattr(task, "theta_labels", None) or []) or None,
            "context_labels": list(getattr(task, "context_labels", None) or []) or None, "train": trained,
            "test": per_context, "methods": summarise(per_context),
            "budget": budget, "target_fraction": TARGET_FRACTION, "train_seconds": t_train,
            "wall_seconds": time.perf_counter() - t0, "versions": library_versions()}


def contexts_table(payload: dict) -> str:
    """The methods side by side, means over the test contexts (what ``corl bench contexts`` prints)."""
    m = payload["methods"]
    lines = [f"{'method':12s} {'first trial ok':>15s} {'trials to 95%':>14s} {'failures':>9s} {'until 95%':>10s} "
             f"{'final R / best':>15s} {'trials':>7s} {'to 95% known':>13s} {'R / known':>10s}"]
    for name in METHODS:
        r = m[name]
        lines.append(f"{name:12s} {100 * r['first_trial_success']:14.0f}% {r['trials_to_95']:14.2f} "
                     f"{r['failures']:9.2f} {r['failures_to_95']:10.2f} {r['final_return_ratio']:15.3f} "
                     f"{r['trials']:7.1f} {r['trials_to_95_known']:13.2f} {r['final_return_known']:10.3f}")
    n, k = len(payload["train"]), len(payload["test"])
    lines.append(f"(means over {k} test contexts; skill trained on {n} contexts; budget {payload['budget']} trials; "
                 f"target R >= R_best - {1 - payload['target_fraction']:.2f} |R_best| of a "
                 f"{payload['test'][0]['sweep_points']}-point sweep per context; 'known': the best return "
                 "the sweep or any method saw there)")
    return "\n".join(lines)


def plot_contexts(payload: dict, path, *, labels=None) -> Path:
    """theta*(c) learned against the sweep's: per theta coordinate, the skill's first theta and the
    contextual run's final theta* against the sweep's best theta, one point per test context."""
    from corl.experiments.figures import _pyplot, _save

    plt = _pyplot()
    tests = payload["test"]
    m = len(tests[0]["theta_swept"])
    labels = list(labels) if labels is not None else [f"theta {j + 1}" for j in range(m)]
    fig, axes = plt.subplots(1, m, figsize=(4.2 * m, 4.0), squeeze=False)
    for j, ax in enumerate(axes[0]):
        swept = np.array([t["theta_swept"][j] for t in tests])
        skill = np.array([t["policy"]["theta"][j] for t in tests])
        final = np.array([np.nan if t["contextual"]["theta"] is None else t["contextual"]["theta"][j] for t in tests])
        lo, hi = float(np.nanmin([swept.min(), skill.min(), np.nanmin(final)])), float(np.nanmax(
            [swept.max(), skill.max(), np.nanmax(final)]))
        pad = 0.05 * (hi - lo or 1.0)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="0.6", lw=1, label="learned = swept")
        ax.scatter(swept, skill, marker="o", label="skill.policy(c), no trial")
        ax.scatter(swept, final, marker="x", label="contextual run's theta*")
        ax.set_xlabel(f"sweep's best {labels[j]}")
        ax.set_ylabel(f"learned {labels[j]}")
        ax.set_title(f"theta*(c), {len(tests)} test contexts")
        ax.legend(fontsize=7)
    return _save(plt, fig, path)
