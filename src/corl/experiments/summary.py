"""The result of one learning run (``corl run``): ``summary.json`` and its human-readable text."""

from __future__ import annotations

from pathlib import Path

__all__ = ["run_summary", "task_extras", "run_text"]


def run_summary(task, method: str, seed: int, learner, seconds: float) -> dict:
    """The fields of ``summary.json`` every task has: best theta (m,), best return, J, trials, failures."""
    from corl.learner import cost_of
    from corl.versions import library_versions

    history, best = learner.history, learner.best
    return {
        "task": task.name, "method": method, "seed": seed,
        "success": best is not None,
        "best_theta": None if best is None else [float(v) for v in best.theta],
        "best_return": None if best is None else best.return_,
        "J_initial": cost_of(task, history[0][0].w) if history else None,
        "J_final": None if best is None else best.J,
        "trials": len(history),
        "failures": sum(not o.success for _, o in history),
        "seconds": seconds,
        "versions": library_versions(),
    }


def task_extras(task, learner) -> dict:
    """Door-style extras: the demonstration's J and return, the final return and door angle."""
    if not hasattr(task, "simulate") or not learner.history:
        return {}
    from corl.learner import cost_of

    demo_p, demo_o = learner.history[0]
    best = learner.best
    final = task.simulate(best.w)
    return {"J_demo": cost_of(task, demo_p.w), "return_demo": demo_o.return_,
            "return_final": best.return_, "door_angle_final": float(final.hinge_final)}


def run_text(summary: dict, path: str | Path) -> str:
    """A few lines for a person: what ran, the best trial, the files written (``path``: summary.json)."""
    s = summary
    lines = [f"run {s.get('run_id', '?')}: {s['method']} on {s['task']}, seed {s['seed']}: {s['trials']} trials, "
             f"{s['failures']} failures, {s['seconds']:.1f} s"]
    if s["best_return"] is None:
        lines.append("no successful trial")
    else:
        J0 = "" if s["J_initial"] is None else f" (demonstration {s['J_initial']:.4g})"
        lines.append(f"best return {s['best_return']:+.4f} at theta {[round(v, 4) for v in s['best_theta']]}, "
                     f"J {s['J_final']:.4g}{J0}")
    files = s.get("files", {})
    lines.append("wrote " + ", ".join([str(path)] + [v for k, v in files.items() if not k.endswith("_skipped")]))
    lines += [f"{k}: {v}" for k, v in files.items() if k.endswith("_skipped")]
    return "\n".join(lines)
