"""What a learning run leaves in its output folder besides summary.json: figures and a video."""

from __future__ import annotations

from pathlib import Path

__all__ = ["write_run_artifacts"]


def write_run_artifacts(task, learner, out: Path, *, video: bool = True) -> dict[str, str]:
    """Learning curve (Fig. 2b), return map (Fig. 2c) and, for simulated tasks with a renderer,
    a video of the demonstration beside the learned motion. Returns {name: path}."""
    from corl.experiments.figures import plot_learning_curve, plot_return_map

    out = Path(out)
    files = {"learning_curve": str(plot_learning_curve(learner, out / "learning_curve.png"))}
    if getattr(learner, "optimizers", None) and task.theta_bounds.dim <= 2:
        labels = getattr(task, "theta_labels", ("theta 1", "theta 2"))
        files["return_map"] = str(plot_return_map(learner, out / "return_map.png", labels=labels))
    render = getattr(task, "render_comparison", None)
    if video and render is not None and learner.best is not None and learner.history:
        try:
            files["video"] = str(render(learner.history[0][0].w, learner.best.w, out / "demo_vs_learned.mp4"))
        except Exception as exc:  # no OpenGL on this machine: the run's results stand without it
            files["video_skipped"] = (f"{type(exc).__name__}: {exc}. Offscreen rendering needs EGL or "
                                      "OSMesa (Debian: libegl1 libgl1); set MUJOCO_GL=egl or osmesa")
    return files
