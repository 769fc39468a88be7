"""Figures of a CORL run: the learning curve of J (Fig. 2b) and the learned return map (Fig. 2c).

Both take a finished (or running) :class:`corl.learner.CORL`; matplotlib is imported lazily and
uses the Agg backend, so they work on machines without a display.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["plot_learning_curve", "plot_return_map"]

_MOTION_STEPS = ("demonstration", "optimization", "phase")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(plt, fig, path) -> Path:
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_learning_curve(learner, path: str | Path, *, title: str = "Motion optimization (Fig. 2b)") -> Path:
    """J(w) of every motion-optimization rollout, in order, with the black-box steps marked.

    x: iteration of the optimization step (0 = demonstration); y: J on a log scale. A dashed
    line marks where step 2 of Algorithm 1 (reinforcement learning over theta) ran, with the
    number of its trials.
    """
    plt = _pyplot()
    J_of = dict(learner.J_history)
    xs, ys, colors, marks = [], [], [], []
    rl_trials = 0
    for proposal, _ in learner.history:
        if proposal.step in _MOTION_STEPS:
            if rl_trials:
                marks.append((len(xs) - 0.5, rl_trials))
                rl_trials = 0
            xs.append(len(xs))
            ys.append(max(J_of[proposal.index], 1e-10))  # J can reach exactly 0; keep the log axis readable
            colors.append("tab:orange" if proposal.step == "phase" else "tab:blue")
        else:
            rl_trials += proposal.step == "reinforcement"
    if rl_trials:
        marks.append((len(xs) - 0.5, rl_trials))
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(xs, ys, color="0.6", lw=1, zorder=1)
    ax.scatter(xs, ys, c=colors, s=12, zorder=2)
    for x, n in marks:
        ax.axvline(x, color="tab:red", ls="--", lw=1)
        ax.annotate(f"RL over theta: {n} trials", (x, min(ys)), rotation=90, va="bottom", ha="right",
                    fontsize=8, color="tab:red")
    ax.set_yscale("log")
    ax.set_xlabel("iteration (rollouts of the optimization step)")
    ax.set_ylabel("J(w) (squared accelerations)")
    ax.set_title(title)
    ax.scatter([], [], c="tab:blue", s=12, label="trajectory step")
    if "tab:orange" in colors:
        ax.scatter([], [], c="tab:orange", s=12, label="phase step")
    ax.legend(loc="upper right", fontsize=8)
    return _save(plt, fig, path)


def _data(learner):
    """theta (d, m), success (d,), returns (d,) of every black-box trial, demonstration included."""
    opt = learner.optimizers[-1] if learner.optimizers else None
    if opt is None:
        raise ValueError("the learner has not run a black-box step yet: there is no return map")
    return opt, opt.X_, opt.success_, opt.returns_


def plot_return_map(learner, path: str | Path, *, regression=None, classifier=None,
                    labels=("theta 1", "theta 2"), title: str = "Learned return R(theta) (Fig. 2c)") -> Path:
    """GP mean of R over theta with successes (blue), failures (red), the classifier's decision
    boundary (red line, p = 0.5) and the best theta (magenta star). 1-D or 2-D theta."""
    from corl.optimizers.gpconfig import ClassifierConfig, RegressionConfig

    plt = _pyplot()
    opt, X, s, r = _data(learner)
    cfg = getattr(opt, "config", None)
    regression = regression or getattr(cfg, "regression", None) or RegressionConfig()
    classifier = classifier or getattr(cfg, "classifier", None) or ClassifierConfig()
    ok = s & np.isfinite(r)
    reg = regression.build().fit(X[ok], r[ok])
    clf = classifier.build().fit(X, s)
    bounds = learner.task.theta_bounds
    best = learner.best
    fig, ax = plt.subplots(figsize=(6, 4.5))
    if bounds.dim == 1:
        g = np.linspace(bounds.lower[0], bounds.upper[0], 600)[:, None]
        mu, var = reg.predict(g)
        p = clf.predict_proba(g)
        ax.plot(g[:, 0], mu, color="k", lw=1.5, label="GP mean of R")
        ax.fill_between(g[:, 0], mu - 2 * np.sqrt(var), mu + 2 * np.sqrt(var), color="0.85")
        lo, hi = np.nanmin(r[ok]) - 1, np.nanmax(r[ok]) + 1
        ax.fill_between(g[:, 0], lo, hi, where=p > 0.5, color="tab:green", alpha=0.08, label="predicted success")
        ax.set_ylim(lo, hi)
        ax.scatter(X[ok, 0], r[ok], c="tab:blue", s=18, zorder=3, label="success")
        ax.scatter(X[~s, 0], np.full((~s).sum(), lo + 0.1), c="tab:red", marker="x", s=30, zorder=3, label="failure")
        ax.scatter([best.theta[0]], [best.return_], c="magenta", marker="*", s=200, zorder=4, label="best")
        ax.set_xlabel(labels[0])
        ax.set_ylabel("R")
    elif bounds.dim == 2:
        n = 120
        a = np.linspace(bounds.lower[0], bounds.upper[0], n)
        b = np.linspace(bounds.lower[1], bounds.upper[1], n)
        A, B = np.meshgrid(a, b)
        G = np.column_stack([A.ravel(), B.ravel()])
        mu, _ = reg.predict(G)
        p = clf.predict_proba(G)
        cs = ax.contourf(A, B, mu.reshape(n, n), levels=20, cmap="viridis")
        fig.colorbar(cs, ax=ax, label="GP mean of R")
        ax.contour(A, B, p.reshape(n, n), levels=[0.5], colors="red", linewidths=2)
        ax.scatter(X[ok, 0], X[ok, 1], c="tab:blue", edgecolors="white", s=28, label="success")
        ax.scatter(X[~s, 0], X[~s, 1], c="tab:red", edgecolors="white", s=28, label="failure")
        ax.scatter([best.theta[0]], [best.theta[1]], c="magenta", marker="*", s=250, edgecolors="k", label="best")
        ax.plot([], [], color="red", lw=2, label="classifier boundary")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
    else:
        raise ValueError(f"a return map needs 1-D or 2-D theta, this task has m = {bounds.dim}")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    return _save(plt, fig, path)
