"""``corl bench contexts``: one skill across scenes against learning each scene from scratch.

Train on N contexts (the demonstration's own, then N - 1 spread over the box by a Latin
hypercube), every run in one store (:mod:`corl.contexts`), in turn, each learning from the runs
before it, or with K robots in waves of K, each scene from the waves before it
(:mod:`corl.experiments.context_training`). Then, in
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
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from corl.errors import DemonstrationFailedError, InputError
from corl.experiments.context_training import _task, check_robots, train

__all__ = ["METHODS", "TARGET_FRACTION", "draw_contexts", "train", "evaluate_context", "summarise", "bench_contexts",
           "contexts_table", "plot_contexts"]

METHODS = ("contextual", "nearest+CORL", "scratch", "nearest")
TARGET_FRACTION = 0.95  # a trial reaches the target at R >= R_best - (1 - TARGET_FRACTION) |R_best|
GRID_POINTS = 64  # sweep points per test context (spread over theta's dimensions)


def draw_contexts(bounds, count: int, rng: np.random.Generator, *, spread: bool = False) -> np.ndarray:
    """``count`` contexts uniform in the box, (count, k); ``spread``: a Latin hypercube (one per
    stratum of each coordinate), so that training contexts cover the box however few they are."""
    if not spread:
        return bounds.from_unit(rng.random((count, bounds.dim)))
    u = (np.argsort(rng.random((bounds.dim, count)), axis=1).T + rng.random((count, bounds.dim))) / max(count, 1)
    return bounds.from_unit(u)


def parse_truth(text: str) -> tuple[str, int]:
    """``--truth``: ``auto`` (the task's ``best_return()`` when it has one, else ``grid:64``),
    ``task`` (its ``best_return()``, required) or ``grid:N`` (a sweep of N points); ``(kind, N)``."""
    text = str(text).strip()
    if text in ("auto", "task"):
        return text, GRID_POINTS
    kind, _, count = text.partition(":")
    if kind == "grid" and count.isdigit() and 2 <= int(count) <= 1_000_000:
        return "grid", int(count)
    raise InputError(f"--truth {text!r}: give auto, task or grid:N with N an integer in [2, 1000000]")


def _grid(dim: int, points: int = GRID_POINTS) -> tuple[int, ...]:
    side = max(3, int(round(points ** (1.0 / dim))))
    return (side,) * dim


def _truth(scene, truth: tuple[str, int], grid=None) -> dict:
    """The best return reachable in ``scene``: its own ``best_return()`` (a closed form or a dense
    search the task's author wrote), or a sweep of theta's box realised from the scene's
    demonstration after step 1 to convergence (the motion every learner starts to optimise)."""
    from corl.experiments.sweep import _solver, evaluate_points
    from corl.realise import feasible, motion_problem
    from corl.trajectory.solver import solve

    kind, count = truth
    own = getattr(scene, "best_return", None)
    if kind in ("auto", "task") and callable(own):
        value = float(own())
        if not np.isfinite(value):
            raise InputError(f"the task's best_return() gave {value}; it must return a finite number")
        return {"best_truth": value, "truth": "task's best_return()", "theta_truth": None, "truth_points": 0}
    if kind == "task":
        raise InputError("--truth task: the task has no best_return() member; use --truth grid:N")
    demo = scene.demonstration()
    solver = _solver(scene)
    best_motion = solve(motion_problem(scene, demo.theta), demo.w, config=solver)
    if feasible(best_motion, solver):
        demo = type(demo)(best_motion.w, demo.theta)
    bounds = scene.theta_bounds
    sizes = tuple(grid) if grid is not None else _grid(bounds.dim, count)
    axes = [np.linspace(lo, hi, g) for lo, hi, g in zip(bounds.lower, bounds.upper, sizes)]
    points = np.column_stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")])
    success, _, returns = evaluate_points(scene, demo.w, demo.theta, points)
    if not np.any(success):
        return {"best_truth": None, "truth": f"grid:{len(points)} (no theta succeeded)", "theta_truth": None,
                "truth_points": int(len(points))}
    return {"best_truth": float(np.nanmax(returns)), "truth": f"grid:{len(points)}",
            "theta_truth": points[int(np.nanargmax(returns))].tolist(), "truth_points": int(len(points))}


def _reached(outcomes, fraction: float, best: float, budget: int) -> int:
    """The trial (1-based) whose success first reaches ``fraction`` of ``best``; the budget when none did."""
    target = best - (1.0 - fraction) * abs(best)
    return next((i + 1 for i, o in enumerate(outcomes) if o.success and o.return_ >= target), budget)


def _scores(outcomes, best: float, budget: int) -> dict:
    """What one method did in one context, from its trials' outcomes (in order), against ``best``."""
    reach = _reached(outcomes, TARGET_FRACTION, best, budget)
    returns = [o.return_ for o in outcomes if o.success]
    final = max(returns) if returns else None
    ratio = 0.0 if final is None else float(final / best) if best != 0 else float("nan")
    return {"trials": len(outcomes), "first_trial_success": bool(outcomes and outcomes[0].success),
            "trials_to_95": int(reach), "trials_to_99": _reached(outcomes, 0.99, best, budget),
            "reached_95": bool(any(o.success and o.return_ >= best - 0.05 * abs(best) for o in outcomes)),
            "failures": sum(not o.success for o in outcomes),
            "failures_to_95": sum(not o.success for o in outcomes[:reach]),
            "final_return": final, "final_return_ratio": ratio}


def _log(history) -> dict:
    """Every trial of a method: success, return (None on a failure) and theta, in order."""
    return {"success": [bool(o.success) for _, o in history],
            "return": [None if not o.success or o.return_ is None else float(o.return_) for _, o in history],
            "theta": [None if p is None else np.asarray(p.theta, dtype=float).tolist() for p, _ in history]}


def _nearest_corl(scene, skill, c, seed: int, budget: int):
    """CORL in the scene started from the nearest training scene's ``w*`` realised there at its
    ``theta*`` (no data from any other scene): ``(history, first)``, ``first`` the realised start."""
    from corl.contexts.learn import StartedTask
    from corl.experiments.sweep import _solver
    from corl.loop import drive
    from corl.methods import make_method
    from corl.problem import Demonstration, Outcome
    from corl.realise import realise

    anchor = skill.nearest(c)
    done = realise(scene, anchor.w, anchor.theta, anchor.theta, _solver(scene))
    if not done.feasible:  # not realisable here: it cannot be run, a failure without a rollout
        return [(None, Outcome(False, None, {"unrealisable": True}))], None
    learner = make_method("CORL", StartedTask(scene, Demonstration(done.w, anchor.theta)), seed=seed)
    learner.config = replace(learner.config, start_retries=0)  # a start that fails is no demonstration to retry
    try:
        drive(learner, scene, max_trials=budget)
    except DemonstrationFailedError:
        pass  # its start failed: CORL cannot go on from it (the one failed trial is its whole run)
    return list(learner.history), done.w


def evaluate_context(spec: str, seed: int, store: str, context, budget: int, grid=None,
                     truth: tuple[str, int] = ("auto", GRID_POINTS), skill: dict | None = None) -> dict:
    """The four methods and the ground truth in one test context (runs in a worker)."""
    from corl.contexts import ContextualCORL, Skill
    from corl.loop import drive
    from corl.methods import make_method
    from corl.problem import Outcome

    task = _task(spec, seed)
    c = np.asarray(context, dtype=float)
    out = {"context": c.tolist(), "seconds": {}}
    try:
        scene = task.with_context(c)
        scene.demonstration()
    except Exception as exc:  # a user's family: one scene without a demonstration is skipped, not the study
        return {**out, "skipped": f"with_context(c).demonstration() raised {type(exc).__name__}: {exc}"}
    t0 = time.perf_counter()
    try:
        out.update(_truth(scene, truth, grid))
    except InputError:
        raise  # the study's own settings (--truth task on a task without best_return)
    except Exception as exc:  # the task's best_return() or its sweep fails in this scene: named, skipped
        return {**out, "skipped": f"its ground truth raised {type(exc).__name__}: {exc}".splitlines()[0]}
    out["seconds"]["truth"] = time.perf_counter() - t0
    skill = Skill.load(store, task, **(skill or {}))
    policy = skill.policy(c)
    out["policy"] = {"theta": policy.theta.tolist(), "p_success": policy.p_success, "R_mean": policy.R_mean,
                     "R_std": policy.R_std, "nearest": policy.nearest.tolist()}
    histories = {}
    learners = {"contextual": lambda: ContextualCORL(task, c, skill, seed=seed),
                "scratch": lambda: make_method("CORL", scene, seed=seed)}
    for name, build in learners.items():
        t0 = time.perf_counter()
        learner = build()
        try:
            drive(learner, scene, max_trials=budget)
        except DemonstrationFailedError:  # scratch: the scene's demonstration failed there
            if name != "scratch" or len(learner.history) == 0:
                raise
        histories[name] = list(learner.history)
        out["seconds"][name] = time.perf_counter() - t0
        best = learner.best
        out[name] = {"theta": None if best is None else np.asarray(best.theta).tolist()}
    t0 = time.perf_counter()  # nearest: the nearest training context's w* realised here at its theta*, as is
    histories["nearest+CORL"], _ = _nearest_corl(scene, skill, c, seed, budget)
    out["seconds"]["nearest+CORL"] = time.perf_counter() - t0
    first = histories["nearest+CORL"][:1]
    histories["nearest"] = first if first else [(None, Outcome(False, None, {"unrealisable": True}))]
    anchor = skill.nearest(c)
    out["nearest"] = {"theta": anchor.theta.tolist()}
    finals = {name: rows for name, rows in histories.items()}
    seen = [o.return_ for rows in finals.values() for _, o in rows if o.success]
    truth_value = out["best_truth"]
    if truth_value is None and not seen:
        return {**out, "skipped": "no method and no point of the ground truth succeeded in this scene"}
    # the best return known here: the ground truth's, never below the best any method saw
    best = max([v for v in [truth_value] if v is not None] + seen)
    out["best"] = best
    found = [(o.return_, p.theta) for rows in finals.values() for p, o in rows if o.success and p is not None]
    top = max(found, key=lambda f: f[0]) if found else None
    by_truth = out["theta_truth"] is not None and (top is None or truth_value >= top[0])
    out["theta_best"] = (out["theta_truth"] if by_truth or top is None
                         else np.asarray(top[1], dtype=float).tolist())
    out["truth_below_seen"] = bool(truth_value is not None and seen and max(seen) > truth_value)
    for name, rows in finals.items():
        entry = out.setdefault(name, {})
        entry.update(_scores([o for _, o in rows], best, budget))
        entry["log"] = _log(rows)
    return out


def summarise(per_context: list[dict]) -> dict:
    """Means over the test contexts that were not skipped, per method (the ``methods`` table)."""
    rows_all = [r for r in per_context if "skipped" not in r]
    table = {}
    for name in METHODS:
        rows = [r[name] for r in rows_all]
        if not rows:
            continue
        mean = {key: float(np.mean([r[key] for r in rows]))
                for key in ("first_trial_success", "trials_to_95", "trials_to_99", "failures", "failures_to_95",
                            "final_return_ratio", "trials")}
        table[name] = {**mean, "reached_95": int(sum(r["reached_95"] for r in rows)), "contexts": len(rows)}
    return table


@dataclass(frozen=True)
class _Job:
    spec: str
    seed: int
    store: str
    budget: int
    truth: tuple[str, int]
    skill: dict | None

    def __call__(self, context):
        return evaluate_context(self.spec, self.seed, self.store, context, self.budget, truth=self.truth,
                                skill=self.skill)


def bench_contexts(spec: str, *, train_count: int, test_count: int, seed: int, out: Path, budget: int = 40,
                   jobs: int = 1, progress=None, truth: str = "auto", skill: dict | None = None, robots: int = 1,
                   trial_seconds: float = 0.0) -> dict:
    """The whole study; writes ``out/train.corl`` (the skill) and returns the contexts.json payload.

    A ``train.corl`` already in ``out`` from the same study (task, seed, training contexts) is
    reused: its finished runs are kept and an unfinished one is resumed (:func:`train`).
    ``truth``: how each test scene's best return is found (:func:`parse_truth`); ``skill``: the
    skill's settings (:class:`corl.contexts.Skill` keywords, e.g. ``{"p_min": 0.9}``), in training and test.
    ``robots`` K: the training scenes in waves of K robots; ``trial_seconds``: each training trial
    also takes that long (:func:`corl.experiments.context_training.train`; ``train_seconds``: its wall time)."""
    from joblib import Parallel, delayed

    from corl.contexts import context_task
    from corl.versions import library_versions

    how = parse_truth(truth)
    robots, trial_seconds = check_robots(robots, trial_seconds)
    task = context_task(_task(spec, seed))
    if how[0] == "task" and not callable(getattr(task, "best_return", None)):
        raise InputError(f"--truth task: task {spec} has no best_return() member; use --truth grid:N")
    box = task.context_bounds
    rng = np.random.default_rng([seed, 22])
    spread = draw_contexts(box, train_count - 1, rng, spread=True)
    contexts = np.vstack([np.asarray(task.context, dtype=float)[None], spread])
    tests = draw_contexts(box, test_count, np.random.default_rng([seed, 22, 1]))
    store = Path(out) / "train.corl"
    t0 = time.perf_counter()
    trained = train(spec, seed, contexts, store, progress, skill, robots=robots, trial_seconds=trial_seconds)
    t_train = time.perf_counter() - t0
    job = _Job(spec, seed, str(store), budget, how, dict(skill) if skill else None)
    per_context = []
    with Parallel(n_jobs=jobs, return_as="generator") as parallel:
        for i, row in enumerate(parallel(delayed(job)(c) for c in tests)):
            per_context.append(row)
            if progress is not None:
                progress("test", i + 1, len(tests), row)
    return {"task": spec, "seed": seed, "theta_labels": list(getattr(task, "theta_labels", None) or []) or None,
            "context_labels": list(getattr(task, "context_labels", None) or []) or None, "train": trained,
            "test": per_context, "methods": summarise(per_context), "truth": truth, "skill": dict(skill or {}),
            "skipped": {"train": sum("skipped" in r for r in trained), "test": sum("skipped" in r for r in per_context)},
            "budget": budget, "target_fraction": TARGET_FRACTION, "robots": robots, "trial_seconds": trial_seconds,
            "train_seconds": t_train,
            "wall_seconds": time.perf_counter() - t0, "versions": library_versions()}


def contexts_table(payload: dict) -> str:
    """The methods side by side, means over the test contexts (what ``corl bench contexts`` prints)."""
    m = payload["methods"]
    lines = [f"{'method':13s} {'first trial ok':>15s} {'to 95%':>7s} {'to 99%':>7s} {'95% reached':>12s} "
             f"{'failures':>9s} {'until 95%':>10s} {'final R / best':>15s} {'trials':>7s}"]
    for name in METHODS:
        if name not in m:
            continue
        r = m[name]
        lines.append(f"{name:13s} {100 * r['first_trial_success']:14.0f}% {r['trials_to_95']:7.2f} "
                     f"{r['trials_to_99']:7.2f} {r['reached_95']:>6d} of {r['contexts']:<2d} {r['failures']:9.2f} "
                     f"{r['failures_to_95']:10.2f} {r['final_return_ratio']:15.3f} {r['trials']:7.1f}")
    tests = [t for t in payload["test"] if "skipped" not in t]
    n = sum("skipped" not in r for r in payload["train"])
    truth = sorted({t["truth"].split(" ")[0] for t in tests})
    lines.append(f"(means over {len(tests)} test contexts; skill trained on {n} contexts; budget {payload['budget']} "
                 f"trials; best = the ground truth ({', '.join(truth)}) or the best return any method saw there, "
                 f"whichever is higher (a method beat the ground truth in {sum(t['truth_below_seen'] for t in tests)} of "
                 f"{len(tests)}); "
                 "a trial counts from its start, a method's trials to a target are its budget when never reached)")
    for kind in ("train", "test"):
        for r in payload[kind]:
            if "skipped" in r:
                lines.append(f"skipped {kind} context {r['context']}: {r['skipped']}")
    return "\n".join(lines)


def plot_contexts(payload: dict, path, *, labels=None) -> Path:
    """theta*(c) learned against the best known: per theta coordinate, the skill's first theta and
    the contextual run's final theta* against the best theta (the truth's or any method's), one point
    per test context."""
    from corl.experiments.figures import _pyplot, _save

    plt = _pyplot()
    tests = [t for t in payload["test"] if "skipped" not in t and t.get("theta_best") is not None]
    if not tests:
        raise InputError("no test context has a best theta to plot")
    m = len(tests[0]["theta_best"])
    labels = list(labels) if labels is not None else [f"theta {j + 1}" for j in range(m)]
    fig, axes = plt.subplots(1, m, figsize=(4.2 * m, 4.0), squeeze=False)
    for j, ax in enumerate(axes[0]):
        swept = np.array([t["theta_best"][j] for t in tests])
        skill = np.array([t["policy"]["theta"][j] for t in tests])
        final = np.array([np.nan if t["contextual"]["theta"] is None else t["contextual"]["theta"][j] for t in tests])
        lo, hi = float(np.nanmin([swept.min(), skill.min(), np.nanmin(final)])), float(np.nanmax(
            [swept.max(), skill.max(), np.nanmax(final)]))
        pad = 0.05 * (hi - lo or 1.0)
        ax.plot([lo - pad, hi + pad], [lo - pad, hi + pad], color="0.6", lw=1, label="learned = best")
        ax.scatter(swept, skill, marker="o", label="skill.policy(c), no trial")
        ax.scatter(swept, final, marker="x", label="contextual run's theta*")
        ax.set_xlabel(f"best {labels[j]} known")
        ax.set_ylabel(f"learned {labels[j]}")
        ax.set_title(f"theta*(c), {len(tests)} test contexts")
        ax.legend(fontsize=7)
    return _save(plt, fig, path)
