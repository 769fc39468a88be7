"""Every figure corl draws, in one place.

* a CORL run (``corl run``, ``corl report``): the learning curve of J (Fig. 2b) and the learned
  return map (Fig. 2c), from a finished (or running) :class:`corl.learner.CORL`;
* a stored run (``corl report``): J and the return of every trial (:func:`plot_trials`);
* the door study (``corl bench door``): failures and best return over trials (:func:`plot_trial_curves`);
* the ground truth over theta (``corl sweep``): :func:`plot_sweep`.

matplotlib is imported lazily and uses the Agg backend, so they work on machines without a
display. Each writes a PNG and returns its path.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["plot_learning_curve", "plot_return_map", "ReturnMapData", "return_map_data", "plot_trials", "plot_trial_curves", "plot_sweep"]

_MOTION_STEPS = ("demonstration", "skill", "optimization", "phase")


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plain_ticks(fig) -> None:
    """Tick labels that read as the values they mark: no offset ("1e-8+5.569111e-1" above ticks 4..7
    reads as values from 4 to 7) and no common exponent, on every linear axis, colour bars included."""
    from matplotlib.ticker import ScalarFormatter

    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            formatter = axis.get_major_formatter()
            if isinstance(formatter, ScalarFormatter):
                formatter.set_useOffset(False)
                formatter.set_scientific(False)


def _save(plt, fig, path, *, trial: int | None = None) -> Path:
    """Plain tick labels, the trial the figure was drawn at in its corner (it lags a live run), then a PNG."""
    _plain_ticks(fig)
    if trial is not None:
        fig.text(0.995, 0.005, f"drawn at trial {trial}", ha="right", va="bottom", fontsize=8, color="0.35")
    fig.tight_layout(rect=(0, 0.02, 1, 1) if trial is not None else None)
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
    return _save(plt, fig, path, trial=_last_trial(learner))


def _last_trial(learner) -> int | None:
    """Index of the learner's last told trial, None before its first."""
    history = getattr(learner, "history", None)
    return history[-1][0].index if history else None


@dataclass(frozen=True)
class ReturnMapData:
    """What a return map draws, copied out of a learner (:func:`return_map_data`), so that it can be drawn
    while the learner moves on (the dashboard of ``corl serve``).

    ``X`` (d, m) theta of every black-box trial, demonstration included; ``success`` (d,); ``returns``
    (d,); ``bounds`` the task's theta bounds; ``best`` ``(theta (m,), return)`` or None; ``config``
    the black-box optimizer's config (its GP settings), or None; ``trial`` the index of the learner's
    last told trial when the data was copied (printed on the figure), or None.
    """

    X: np.ndarray
    success: np.ndarray
    returns: np.ndarray
    bounds: object
    best: tuple | None
    config: object = None
    trial: int | None = None


def return_map_data(learner) -> ReturnMapData:
    """The last black-box step's data of ``learner``, copied; ValueError before its first black-box step."""
    opt = learner.optimizers[-1] if getattr(learner, "optimizers", None) else None
    if opt is None:
        raise ValueError("the learner has not run a black-box step yet: there is no return map")
    best = learner.best
    return ReturnMapData(np.array(opt.X_, dtype=float), np.array(opt.success_, dtype=bool),
                         np.array(opt.returns_, dtype=float), learner.task.theta_bounds,
                         None if best is None else (np.array(best.theta, dtype=float), float(best.return_)),
                         getattr(opt, "config", None), _last_trial(learner))


def plot_return_map(learner, path: str | Path, *, regression=None, classifier=None,
                    labels=("theta 1", "theta 2"), title: str = "Learned return R(theta) (Fig. 2c)") -> Path:
    """GP mean of R over theta with successes (blue), failures (red), where the classifier predicts
    success (p > 0.5: a green band in 1-D, inside the red boundary line in 2-D) and the learner's best
    theta (magenta star). 1-D or 2-D theta.

    ``learner``: a learner after its first black-box step, or its :class:`ReturnMapData`."""
    data = learner if isinstance(learner, ReturnMapData) else return_map_data(learner)
    return _draw_return_map(data, path, regression=regression, classifier=classifier, labels=labels, title=title)


def _draw_return_map(data: ReturnMapData, path, *, regression, classifier, labels, title) -> Path:
    from corl.optimizers.gpconfig import ClassifierConfig, ModelFitter, RegressionConfig

    plt = _pyplot()
    X, s, r = data.X, data.success, data.returns
    cfg = data.config
    regression = regression or getattr(cfg, "regression", None) or RegressionConfig()
    classifier = classifier or getattr(cfg, "classifier", None) or ClassifierConfig()
    ok = s & np.isfinite(r)
    bounds = data.bounds
    if bounds.dim > 2:
        raise ValueError(f"a return map needs 1-D or 2-D theta, this task has m = {bounds.dim}")
    fitter = ModelFitter(regression, classifier, bounds)  # fixed values as given, or fitted as the learner fits
    reg = fitter.regression(X[ok], r[ok])
    clf = fitter.classifier(X, s)
    best_theta, best_return = data.best if data.best is not None else (None, None)
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
        if best_theta is not None:
            ax.scatter([best_theta[0]], [best_return], c="magenta", marker="*", s=200, zorder=4, label="learner's best")
        ax.set_xlabel(labels[0])
        ax.set_ylabel("R")
    else:  # 2-D (more was refused above, before the fits)
        n = 120
        a = np.linspace(bounds.lower[0], bounds.upper[0], n)
        b = np.linspace(bounds.lower[1], bounds.upper[1], n)
        A, B = np.meshgrid(a, b)
        G = np.column_stack([A.ravel(), B.ravel()])
        mu, _ = reg.predict(G)
        p = clf.predict_proba(G)
        low, high = float(np.min(mu)), float(np.max(mu))
        spread = max(high - low, 1e-3 * max(1.0, abs(high)))  # a flat mean: one colour, not noise in 1e-8 steps
        middle = 0.5 * (low + high)
        levels = np.linspace(middle - spread / 2, middle + spread / 2, 21)
        cs = ax.contourf(A, B, np.clip(mu.reshape(n, n), levels[0], levels[-1]), levels=levels, cmap="viridis")
        fig.colorbar(cs, ax=ax, label="GP mean of R")
        ax.contour(A, B, p.reshape(n, n), levels=[0.5], colors="red", linewidths=2)
        ax.scatter(X[ok, 0], X[ok, 1], c="tab:blue", edgecolors="white", s=28, label="success")
        ax.scatter(X[~s, 0], X[~s, 1], c="tab:red", edgecolors="white", s=28, label="failure")
        if best_theta is not None:
            ax.scatter([best_theta[0]], [best_theta[1]], c="magenta", marker="*", s=250, edgecolors="k",
                       label="learner's best")
        ax.plot([], [], color="red", lw=2, label="classifier boundary")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    return _save(plt, fig, path, trial=data.trial)


def plot_trials(records, J, path: str | Path) -> Path:
    """J (top, log scale) and the return R (bottom) of every told trial, in the order they ran (``corl report``).

    ``records``: the stored trials (:class:`corl.store.TrialRecord`, d of them); ``J``: (d,) their
    analytic costs, NaN where unknown.

    Failures have no return: they are red crosses along the bottom of the lower panel. The black
    step line is the best observed reading so far; dotted vertical lines separate Algorithm 1's rounds.
    """
    plt = _pyplot()
    told = [(i, r) for i, r in enumerate(records) if r.outcome is not None]
    x = np.array([r.index for _, r in told], dtype=float)
    ok = np.array([r.outcome.success for _, r in told], dtype=bool)
    R = np.array([np.nan if r.outcome.return_ is None else r.outcome.return_ for _, r in told], dtype=float)
    J = np.array([J[i] for i, _ in told], dtype=float)
    rounds = np.array([r.proposal.round for _, r in told])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(10, 5.6), sharex=True)
    finite = np.isfinite(J)
    if finite.any():
        Jp = np.maximum(J, 1e-12)  # J can reach exactly 0; keep the log axis readable
        top.scatter(x[finite & ok], Jp[finite & ok], s=9, c="tab:blue", label="success")
        top.scatter(x[finite & ~ok], Jp[finite & ~ok], s=22, c="tab:red", marker="x", label="failure")
        top.set_yscale("log")
        top.legend(loc="upper right", fontsize=8)
    else:
        top.text(0.5, 0.5, "J unavailable (task not loaded)", ha="center", va="center", transform=top.transAxes)
    top.set_ylabel("J(w)")
    top.set_title("J and return over trials")
    good = ok & np.isfinite(R)
    bottom.scatter(x[good], R[good], s=9, c="tab:blue", label="return of a success")
    if good.any():
        best_so_far = np.fmax.accumulate(np.where(good, R, -np.inf))
        shown = np.isfinite(best_so_far)
        bottom.step(x[shown], best_so_far[shown], where="post", color="k", lw=1.2,
                    label="best observed reading so far")
    if (~ok).any():
        bottom.scatter(x[~ok], np.full((~ok).sum(), 0.04), transform=bottom.get_xaxis_transform(), s=30,
                       c="tab:red", marker="x", label=f"failure ({(~ok).sum()}, no return)")
    for change in x[1:][np.diff(rounds) != 0] if len(x) else ():
        for ax in (top, bottom):
            ax.axvline(change - 0.5, color="0.6", ls=":", lw=1)
    bottom.set_xlabel("trial")
    bottom.set_ylabel("return R")
    bottom.legend(loc="upper left", fontsize=8)  # returns tend to rise: the early top is free
    return _save(plt, fig, path, trial=int(x[-1]) if len(x) else None)


def plot_trial_curves(curves: dict[str, dict], path: str | Path) -> Path:
    """Two panels over trials k: failures so far and highest R so far, mean ± std band per method."""
    plt = _pyplot()
    fig, (ax_f, ax_r) = plt.subplots(1, 2, figsize=(10, 4))
    for m, c in curves.items():
        k = np.asarray(c["k"])
        for ax, key in ((ax_f, "failures"), (ax_r, "best")):
            mean = np.asarray(c[f"{key}_mean"], dtype=float)
            std = np.asarray(c[f"{key}_std"], dtype=float)
            line, = ax.plot(k, mean, label=m)
            ax.fill_between(k, mean - std, mean + std, color=line.get_color(), alpha=0.2)
        stops = np.asarray(c["stopped"])
        if stops.max() < len(k):  # mark where the runs stopped by their own rule
            ax_f.axvline(float(np.mean(stops)), color=line.get_color(), ls=":", lw=1,
                         label=f"{m} stops (mean {np.mean(stops):.0f} trials)")
    ax_f.set(xlabel="trials", ylabel="failures so far", title="Failures (Fig. 3 over trials)")
    ax_r.set(xlabel="trials", ylabel="highest R so far", title="Highest return")
    ax_f.legend(loc="upper left")
    ax_f.grid(alpha=0.3)
    ax_r.grid(alpha=0.3)
    return _save(plt, fig, path)


def plot_sweep(sweep, path: str | Path, *, labels=("theta 1", "theta 2"), title: str = "") -> Path:
    """The ground truth of ``corl sweep`` (a :class:`corl.experiments.sweep.Sweep`): R of the successful
    rollouts over theta (a line for 1-D theta, a colour map for 2-D), failures as red crosses and the
    anchor's theta as a star."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 4.5))
    R = np.where(sweep.success, sweep.returns, np.nan)
    if len(sweep.axes) == 1:
        x = sweep.axes[0]
        ax.plot(x, R, "o-", color="C0", label="R (successful rollouts)")
        fails = ~sweep.success
        ax.plot(x[fails], np.full(fails.sum(), np.nanmin(R) if np.isfinite(R).any() else 0.0), "x", color="C3",
                label="failure")
        ax.axvline(sweep.anchor_theta[0], color="k", ls="--", lw=1, label="anchor")
        ax.set_xlabel(labels[0])
        ax.set_ylabel("R")
        ax.legend(loc="best", fontsize=8)
    else:
        t1, t2 = sweep.axes
        image = ax.pcolormesh(t1, t2, R.T, shading="nearest", cmap="viridis")
        fig.colorbar(image, ax=ax, label="R (successful rollouts)")
        P = sweep.points
        fail = ~sweep.success.ravel()
        ax.plot(P[fail, 0], P[fail, 1], "x", color="C3", ms=4, label="failure")
        ax.plot(*sweep.anchor_theta, "k*", ms=10, label="anchor")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
        ax.legend(loc="best", fontsize=8)
    ax.set_title(title or f"success region and return: {int(sweep.success.sum())}/{sweep.success.size} succeed")
    return _save(plt, fig, path)
