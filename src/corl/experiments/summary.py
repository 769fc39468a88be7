"""The result of one learning run (``corl run``): ``summary.json`` and its human-readable text."""

from __future__ import annotations

from pathlib import Path

import numpy as np

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
