"""``corl policy``: the skill a run store learned across contexts, deployed in one scene with no trial
(:class:`corl.contexts.Skill`), and the ``--context`` argument ``corl run`` and ``corl ask`` share.

One store holds the runs of many contexts (``corl run TASK --context C`` adds one); ``corl policy
TASK --store S --context C`` answers for any C of the task's context box: theta, how sure the skill
is, the motion ``w`` and, for a task with ``reference()``, the joint trajectory a robot executes.
Nothing is written when the motion does not satisfy the task's constraint h in that scene.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import typer

from corl.arguments import NEW_PATHS, latest_run, plain_number, plain_numbers
from corl.cli.common import JSON_OUT, check_args, fail, open_store, print_json, write_json
from corl.errors import CorlError, InputError

__all__ = ["policy", "parse_context", "scene_of", "recorded_context", "context_text", "box_text", "P_MIN_OPTION",
           "skill_settings"]

#: ``--p-min``: the skill settings' flag, shared by ``corl run``, ``corl ask``, ``corl policy`` (and ``corl bench
#: contexts``); read it with :func:`skill_settings`.
P_MIN_OPTION = typer.Option(None, "--p-min", help="the skill's start is refined (not explored around) when it "
                                                  "succeeds with at least this probability, in (0, 1); default "
                                                  "0.95 (corl.contexts.P_MIN)")


def box_text(task) -> str:
    """``the context box of task 'door': dz in [-0.05, 0.05], ...``: one coordinate after another."""
    b = task.context_bounds
    labels = getattr(task, "context_labels", None) or [f"c{i + 1}" for i in range(b.dim)]
    coords = ", ".join(f"{label} in [{lo:g}, {hi:g}]" for label, lo, hi in zip(labels, b.lower, b.upper))
    return f"the context box of task '{task.name}': {coords}"


def skill_settings(p_min: str | None, *, context: str | None = "given") -> dict:
    """The skill's settings from the command line as :class:`corl.contexts.Skill` keywords
    (``{"p_min": 0.9}``, only those given), checked before any work: a bad one exits 2 with one line.

    ``context``: the command's ``--context`` (None: not given), for commands where a skill setting
    needs one (``corl run``, ``corl ask``); leave it for those that always learn in scenes.
    """
    from corl.checks import number

    given = {}
    try:
        if p_min is not None:
            given["p_min"] = number("--p-min", plain_number("--p-min", p_min), low=0.0, high=1.0, low_open=True,
                                    high_open=True)
    except CorlError as exc:
        fail(f"{exc}: a success probability, e.g. --p-min 0.9")
    if given and context is None:
        fail(f"--{next(iter(given)).replace('_', '-')} sets the skill a run in a context starts from: add "
             "--context C, or drop it")
    return given


def context_text(c) -> str:
    """A context as ``--context`` takes it: ``0.02,-0.01,0,0.1``; ``none`` for no context."""
    return "none" if c is None else ",".join(f"{float(v):.6g}" for v in c)


def parse_context(the_task, text: str):
    """``--context TEXT`` as a point (k,) of the task's context box, or one :class:`InputError` naming
    the box: a task without contexts, a number that is no plain finite one, a wrong count, outside."""
    import numpy as np

    from corl.contexts import context_task
    from corl.session import check_context

    try:
        context_task(the_task)
    except InputError as exc:
        raise InputError(f"{exc}; drop --context") from None
    box = box_text(the_task)
    try:
        values = plain_numbers("--context", text)
    except InputError as exc:
        raise InputError(f"{exc}; {box}") from None
    k = the_task.context_bounds.dim
    if len(values) != k:
        raise InputError(f"--context {text} gives {len(values)} number{'s' if len(values) > 1 else ''}, but task "
                         f"'{the_task.name}' has {k} context coordinate{'s' if k > 1 else ''}: give "
                         f"{'one number' if k == 1 else f'{k} comma-separated numbers'} inside {box}")
    c = np.array(values, dtype=float)
    if not the_task.context_bounds.contains(c):
        raise InputError(f"--context {text} is outside {box}; corl learns and deploys the skill inside it only")
    return check_context(the_task, c)


def scene_of(the_task, context):
    """The task in ``context`` (its own object when that is its own context): where a run rolls out."""
    import numpy as np

    from corl.contexts.skill import scene_of as checked_scene

    if context is None or np.array_equal(np.asarray(context, dtype=float), np.asarray(the_task.context, dtype=float)):
        return the_task
    return checked_scene(the_task, np.asarray(context, dtype=float))


def recorded_context(info):
    """The context a stored run records (``config["context"]``) as an array, or None."""
    import numpy as np

    c = info.config.get("context")
    return None if c is None else np.asarray(c, dtype=float).reshape(-1)


def policy(
    task: str = typer.Argument(..., help="the task the store learned: 'synthetic-context', 'door' or "
                                         "'package.module:make_task'"),
    store: Path = typer.Option(..., help="run store holding runs in one or more contexts (only read)"),
    context: str = typer.Option(..., help="the scene: comma-separated numbers, one per context coordinate, "
                                          "e.g. 0.02,-0.01,0,0.1"),
    out: Optional[Path] = typer.Option(None, help="folder for policy.json (and policy.csv/.npz, the joint "
                                                  "trajectory); default: beside the store"),
    rate: float = typer.Option(100.0, help="rate of the written trajectory (Hz), for a task with reference()"),
    p_min: Optional[str] = P_MIN_OPTION,
    json_out: bool = JSON_OUT,
) -> None:
    """The learned skill in context C, with no trial: theta, p_success, R, the motion (policy.json, and the joint
    trajectory policy.csv/.npz for a task with reference())."""
    folder = out if out is not None else store.parent
    check_args(task=("TASK", task), path=("--store", store), rate=("--rate", rate), folder=("--out", folder))
    skill_kw = skill_settings(p_min)
    if store.is_dir():
        fail(f"--store {store} is a folder; give the store file, e.g. {store / 'run.corl'}")
    if not store.is_file():
        fail(f"--store {store} does not exist; learn a context into it first: corl run {task} --context C "
             f"--store {store}")
    NEW_PATHS.track(folder)
    try:
        info = latest_run(store)  # read-only
        if info is None:
            fail(f"{store} holds no run, so no skill; learn a context first: corl run {task} --context C "
                 f"--store {store}")
        the_task, skill, answer, trajectory = _deployed(task, store, context, rate, info, skill_kw)
    except CorlError as exc:
        fail(str(exc))
    payload = _payload(the_task, store, skill, answer, rate)
    path = folder / "policy.json"
    payload["files"] = {"policy": str(path)}
    if trajectory is not None:
        payload["files"].update(_write_trajectory(folder, the_task, answer, trajectory))
    write_json(path, payload)
    if json_out:
        return print_json(payload)
    typer.echo(_table(payload))


def _deployed(task: str, store: Path, text: str, rate: float, info, skill_kw: dict):
    """``(task, skill, policy, trajectory or None)``; every refusal an error before anything is written."""
    import numpy as np

    from corl.contexts import Skill
    from corl.session import trajectory_of
    from corl.tasks.registry import load_task

    the_task = load_task(task, seed=int(info.seed or 0))
    c = parse_context(the_task, text)
    with open_store(store, readonly=True) as db:
        skill = Skill.load(db, the_task, **skill_kw)
    answer = skill.policy(c)
    if not answer.feasible:
        raise InputError(f"the skill's motion for --context {context_text(c)} does not satisfy the task's "
                         "constraint h there (Eq. 18 found no motion realising its theta from the nearest learned "
                         f"context {context_text(answer.nearest)}), so no policy is written: learn this "
                         f"context first (corl run {task} --context {context_text(c)} --store {store})")
    trajectory = None
    if getattr(the_task, "reference", None) is not None:  # corl.problem.HasReference
        t, q = trajectory_of(scene_of(the_task, c), np.asarray(answer.w, dtype=float), rate)
        trajectory = (t, q)
    return the_task, skill, answer, trajectory


def _number(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None  # JSON has no NaN: a skill with no success yet


def _payload(the_task, store: Path, skill, answer, rate: float) -> dict:
    return {
        "task": the_task.name, "store": str(store),
        "context": [float(v) for v in answer.context],
        "context_labels": list(getattr(the_task, "context_labels", None) or []),
        "theta": [float(v) for v in answer.theta],
        "theta_labels": list(getattr(the_task, "theta_labels", None) or []),
        "p_success": _number(answer.p_success), "R_mean": _number(answer.R_mean), "R_std": _number(answer.R_std),
        "J": _number(answer.J), "nearest": [float(v) for v in answer.nearest], "feasible": bool(answer.feasible),
        "learned_contexts": [[float(v) for v in a.context] for a in skill.anchors],
        "trials": len(skill.data), "p_min": skill.p_min,
        "w": [float(v) for v in answer.w],
        "rate": rate if getattr(the_task, "reference", None) is not None else None,
    }


def _write_trajectory(folder: Path, the_task, answer, trajectory) -> dict:
    """policy.csv (t and one column per joint, as ``corl ask`` writes a trial) and policy.npz, each whole
    or not at all (:func:`corl.store.files.write_atomically`)."""
    import numpy as np

    from corl.store.files import write_atomically

    t, q = trajectory
    names = getattr(the_task, "joint_names", None) or [f"q{j}" for j in range(q.shape[1])]
    csv, npz = folder / "policy.csv", folder / "policy.npz"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        write_atomically(npz, lambda tmp: np.savez(tmp, t=t, q=q, w=answer.w, theta=answer.theta,
                                                   context=answer.context))
        write_atomically(csv, lambda tmp: np.savetxt(tmp, np.column_stack([t, q]), delimiter=",",
                                                     header="t," + ",".join(names), comments=""))
    except OSError as exc:
        fail(f"cannot write the policy to {folder}: {exc.strerror}; give another --out")
    except CorlError as exc:
        fail(str(exc))
    return {"csv": str(csv), "npz": str(npz)}


def _table(p: dict) -> str:
    def vec(values) -> str:
        return "[" + ", ".join(f"{v:.4g}" for v in values) + "]"

    r = "-" if p["R_mean"] is None else f"{p['R_mean']:+.4f} ± {p['R_std']:.4f}"
    rows = [("context", vec(p["context"])), ("theta", vec(p["theta"])),
            ("p_success", "-" if p["p_success"] is None else f"{p['p_success']:.3f}"), ("R_mean ± R_std", r),
            ("J", "-" if p["J"] is None else f"{p['J']:.4g}"), ("nearest learned context", vec(p["nearest"])),
            ("learned contexts", f"{len(p['learned_contexts'])} ({p['trials']} trials)")]
    head = f"policy of task '{p['task']}' from {p['store']} (no trial)"
    lines = [head] + [f"  {name:<24} {value}" for name, value in rows]
    lines.append("wrote " + ", ".join(p["files"].values()))
    if p["p_success"] is not None and p["p_success"] < p["p_min"]:
        lines.append(f"note: the skill predicts success with probability {p['p_success']:.2f} only (< {p['p_min']}): "
                     "learn this context (corl run/ask --context) before trusting it")
    return "\n".join(lines)
