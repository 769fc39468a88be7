"""What one learning run (``corl run``) leaves in its output folder.

* ``summary.json``: :func:`run_summary` (the fields every task has) and :func:`task_extras` (the
  demonstration's numbers and what the best trial measured); :func:`run_text` says it in a few lines;
* figures: :func:`write_run_artifacts` (the learning curve, the return map); with ``corl run
  --video``, :func:`write_run_video` (for a task that renders, the demonstration beside the learned
  motion).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from corl.experiments.figures import plot_learning_curve, plot_return_map
from corl.mujoco.video import RENDERING_HINT

__all__ = ["run_summary", "task_extras", "run_text", "write_run_artifacts", "write_run_video"]


def run_summary(task, method: str, seed: int, learner, seconds: float, *, context=None,
                contextual: bool = False) -> dict:
    """The fields of ``summary.json`` every task has: best theta (m,), best return, J, trials, failures;
    for a task with contexts also ``context`` (k,), the scene the run learned in, and for a run in a
    context (``corl run --context``) ``start``: what its first trial was (the skill's policy, the
    nearest learned context's theta*, the scene's demonstration; the demonstration in the first context)."""
    from corl.learner import cost_of
    from corl.session import best_record
    from corl.versions import library_versions

    history, best = learner.history, learner.best
    summary = {
        "task": task.name, "method": method, "seed": seed,
        "success": best is not None,
        "best_theta": None if best is None else [float(v) for v in best.theta],
        "best_return": None if best is None else best.return_,  # the learner's best: what to deploy
        "best_return_std": None if best is None or not np.isfinite(getattr(best, "return_std", np.nan))
        else float(best.return_std),
        "best_trial": None if best is None else best_record(learner)["trial"],
        "best_observed": _observed(learner),  # the highest reading (under noise, the luckiest): not deployed
        "J_initial": cost_of(task, history[0][0].w) if history else None,
        "J_final": None if best is None else best.J,
        "trials": len(history),
        "failures": sum(not o.success for _, o in history),
        # why the learner stopped (corl.optimizers.base.StopReason); None for a run cut short
        "stop_reason": None if getattr(learner, "stop_reason", None) is None else learner.stop_reason.value,
        "stop_detail": getattr(learner, "stop_detail", ""),  # CORL: which loop of Algorithm 1 stopped, in words
        "seconds": seconds,
        "versions": library_versions(),
    }
    if context is not None:
        summary["context"] = [float(v) for v in np.asarray(context, dtype=float).reshape(-1)]
    if contextual:
        summary["start"] = getattr(learner, "start_kind", None) or "demonstration"  # corl.contexts.ContextualCORL
    return summary


def _observed(learner) -> dict | None:
    from corl.learner import best_observed

    found = best_observed(getattr(learner, "history", []))
    if found is None:
        return None
    p, o = found
    return {"trial": p.index, "return": float(o.return_), "theta": [float(v) for v in np.asarray(p.theta).reshape(-1)]}


def task_extras(task, learner) -> dict:
    """The demonstration's J and return, the final return, and the numbers the best trial measured.

    Read from the learner's history only (no task member is called): ``final_info`` holds the
    numeric entries of the best trial's ``Outcome.info`` (the door's ``hinge_final``, ...). For
    the door, ``door_angle_final`` repeats ``hinge_final`` (rad) under its old name.
    """
    if not learner.history:
        return {}
    from corl.learner import cost_of

    demo_p, demo_o = learner.history[0]
    best = learner.best
    extras = {"J_demo": cost_of(task, demo_p.w), "return_demo": demo_o.return_,
              "return_final": None if best is None else best.return_}
    if best is None:
        return extras
    info = next((dict(o.info) for p, o in reversed(learner.history) if o.success and np.array_equal(p.w, best.w)), {})
    numbers = {k: float(v) for k, v in info.items()
               if isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)}
    extras["final_info"] = numbers
    if "hinge_final" in numbers:
        extras["door_angle_final"] = numbers["hinge_final"]
    return extras


def run_text(summary: dict, path: str | Path) -> str:
    """A few lines for a person: what ran, the best trial, the files written (``path``: summary.json)."""
    s = summary
    scene = "" if s.get("context") is None else f" in context {[round(v, 4) for v in s['context']]}"
    scene += f" (started from the {s['start']})" if s.get("start") else ""
    lines = [f"run {s.get('run_id', '?')}: {s['method']} on {s['task']}{scene}, seed {s['seed']}: {s['trials']} "
             f"trials, {s['failures']} failures, {s['seconds']:.1f} s"]
    if s["best_return"] is None:
        lines.append("no successful trial")
    else:
        start = "demonstration" if s.get("start") in (None, "demonstration") else f"start: {s['start']},"
        J0 = "" if s["J_initial"] is None else f" ({start} {s['J_initial']:.4g})"
        std = "" if s.get("best_return_std") is None else f" +- {s['best_return_std']:.3g}"
        lines.append(f"learner's best: return {s['best_return']:+.4f}{std} at theta "
                     f"{[round(v, 4) for v in s['best_theta']]}, J {s['J_final']:.4g}{J0}")
        seen = s.get("best_observed")
        if seen is not None and seen["trial"] != s.get("best_trial") and seen["return"] > s["best_return"]:
            lines.append(f"best observed: reading {seen['return']:+.4f} at trial {seen['trial']} (not the learner's best)")
    if s.get("noise"):  # corl run --return-noise / --flip (corl.tasks.NoisyTask)
        n, true = s["noise"], s.get("final_info", {}).get("true_return")
        lines.append(f"read through noisy sensors (return noise {n['return_noise']:g}, flip {n['flip']:g})"
                     + ("" if true is None else f": the best trial's true return {true:+.4f}"))
    if s.get("ended"):  # corl run --resume --end-at-error
        e = s["ended"]
        lines.append(f"ended at trial {e['trial']}, where the task's {e['member']} raised {e['error']}")
    files = s.get("files", {})
    lines.append("wrote " + ", ".join([str(path)] + [v for k, v in files.items() if not k.endswith("_skipped")]))
    lines += [f"{k}: {v}" for k, v in files.items() if k.endswith("_skipped")]
    return "\n".join(lines)


def write_run_artifacts(task, learner, out: Path) -> dict[str, str]:
    """Learning curve (Fig. 2b) and return map (Fig. 2c); the video is :func:`write_run_video`'s.
    Returns {name: path}."""
    out = Path(out)
    files = {"learning_curve": str(plot_learning_curve(learner, out / "learning_curve.png"))}
    if getattr(learner, "optimizers", None) and task.theta_bounds.dim <= 2:
        labels = getattr(task, "theta_labels", ("theta 1", "theta 2"))
        files["return_map"] = str(plot_return_map(learner, out / "return_map.png", labels=labels))
    return files


def write_run_video(task, learner, out: Path) -> dict[str, str]:
    """For a task with ``render_comparison``: ``{"video": path}`` of the demonstration beside the best
    motion, ``{"video_skipped": why}`` when this machine cannot render, ``{}`` for other tasks."""
    render = getattr(task, "render_comparison", None)
    if render is None or learner.best is None or not learner.history:
        return {}
    try:
        return {"video": str(render(learner.history[0][0].w, learner.best.w, Path(out) / "demo_vs_learned.mp4"))}
    except Exception as exc:  # no OpenGL on this machine: the run's results stand without it
        return {"video_skipped": f"{type(exc).__name__}: {exc}. {RENDERING_HINT}"}
