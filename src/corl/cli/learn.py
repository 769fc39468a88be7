"""``corl run``, ``corl ask`` and ``corl tell``: a learning run, in the simulator or trial by trial on a
robot, every trial committed to the run store (:mod:`corl.session`).

With ``--context C`` (a task with contexts), ``corl run`` and ``corl ask`` start a new run in scene C
that learns from the store's earlier runs in other contexts (:mod:`corl.contexts`); one store holds
them all, and ``corl policy`` (:mod:`corl.cli.skill`) deploys what they learned."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Optional

import typer

from corl.arguments import NEW_PATHS, latest_run, plain_number
from corl.cli.common import (JSON_OUT, LOG, QUIET, check_args, fail, make_folder, open_store, print_json,
                             progress_tracker, write_json)
from corl.cli.skill import P_MIN_OPTION, context_text, parse_context, recorded_context, scene_of, skill_settings

__all__ = ["run", "ask", "tell"]


def run(
    task: str = typer.Argument(..., help="'synthetic', or an import path 'package.module:make_task'"),
    method: Optional[str] = typer.Option(None, help="method name: CORL or a row of Fig. 1 (default: CORL+PIBU for "
                                                     "the built-in tasks, CORL for your own)"),
    seed: Optional[int] = typer.Option(None, help="seed (default 0)"),
    out: Path = typer.Option(Path("results/run"), help="output folder for summary.json"),
    store: Optional[Path] = typer.Option(None, help="run store (default OUT/run.corl)"),
    resume: bool = typer.Option(False, "--resume", help="continue the store's latest run exactly (or start one)"),
    context: Optional[str] = typer.Option(None, help="learn in this scene (a task with contexts): comma-separated "
                                                     "numbers, e.g. 0.02,-0.01,0,0.1; a new run in the store that "
                                                     "starts from what its runs in other contexts learned"),
    p_min: Optional[str] = P_MIN_OPTION,
    quiet: bool = QUIET, json_out: bool = JSON_OUT, log: bool = LOG,
    video: bool = typer.Option(False, "--video/--no-video", help="after learning, render the demonstration beside "
                                                                  "the learned motion (tasks that render)"),
    rollout_every_step: Optional[bool] = typer.Option(
        None, "--rollout-every-step/--no-rollout-every-step",
        help="roll out every motion-optimization step (default: the task's CORLConfig), or only the converged one"),
    return_noise: Optional[str] = typer.Option(
        None, "--return-noise", help="try the task with a noisy return sensor: the std of a Gaussian error added to "
                                     "every return, in the return's units (corl.tasks.NoisyTask; default 0)"),
    flip: Optional[str] = typer.Option(
        None, "--flip", help="try the task with a flaky success sensor: the probability in [0, 0.5) that a trial's "
                             "success is reported flipped (never the demonstration's; default 0)"),
    robots: Optional[int] = typer.Option(
        None, "--robots", help="K simulated robots: up to K trials out at once, each in a worker process "
                               "(CORL's black-box step; default 1)"),
    backend: str = typer.Option("local", help="where --robots run: local (processes), ray (Ray actors) or dask (Dask "
                                               "workers), on a local cluster of K unless --address"),
    address: Optional[str] = typer.Option(None, help="with --backend ray or dask: a running cluster to join "
                                                     "(its workers need corl and the task's code)"),
    end_at_error: bool = typer.Option(
        False, "--end-at-error", help="with --resume: where the task's code raised on the run's last told trial, "
                                      "end the run there (every trial kept, none run) and write its summary"),
) -> None:
    """One learning run, every trial committed to the store; writes OUT/summary.json, figures (and with --video
    a video, rendered once after the store is closed: learning never waits for it)."""
    import time

    from corl.errors import CorlError, TaskError
    from corl.experiments.run_output import run_summary, run_text, task_extras, write_run_artifacts, write_run_video
    from corl.methods import METHODS

    store_path = store or out / "run.corl"
    check_args(task=("TASK", task), seed=("--seed", seed), folder=("--out", out), store=("--store", store_path))
    if method is not None and method not in METHODS:
        fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    if end_at_error and not resume:
        fail("--end-at-error ends the run being resumed; add --resume")
    if robots is not None and not 1 <= robots <= 64:
        fail(f"--robots must be an integer in [1, 64], got {robots}")
    if (robots or 1) > 1 and (return_noise is not None or flip is not None or context is not None):
        fail("--robots with --return-noise, --flip or --context is not done (one robot per scene, sensors read "
             "in each worker): drop one of them")
    skill = skill_settings(p_min, context=context)
    try:
        sensors = _sensor_flags(return_noise, flip)
    except CorlError as exc:
        fail(str(exc))
    NEW_PATHS.track(out, store_path)
    make_folder("--out", out)  # where summary.json goes, checked before any trial
    t0 = time.perf_counter()
    renders, why = _rendering() if video else (True, "")  # before the task imports MuJoCo: a backend that works
    if not renders:  # asked for a video it cannot have: said before any trial
        fail(f"--video: {why} (or run without --video)")
    try:  # every check, the task and the learner (replayed) before the store is opened for writing
        the_task, session, seen = _run_to_continue(task, store_path, resume=resume, method=method, seed=seed,
                                                   rollout_every_step=rollout_every_step, quiet=quiet, context=context,
                                                   sensors=sensors, end_at_error=end_at_error, skill=skill,
                                                   robots=robots)
        from corl.fleet import check_backend

        check_backend(backend, address)
        if end_at_error and session.ended is None:
            fail(f"run {session.run_id} in {store_path} resumes without an error of the task's code, so there is "
                 "nothing to end it at: drop --end-at-error to go on with it")
        db = open_store(store_path)
    except CorlError as exc:
        fail(str(exc))
    with db:
        try:
            if session.run_id is None and seen is not None:  # learned from the store's runs: still the same?
                _refuse_new_runs(db, store_path, seen[0])
            info = db.run(session.attach(db).run_id)
        except CorlError as exc:
            fail(str(exc))
        method, seed = info.method, int(info.seed or 0)

        import numpy as np

        def line(p, o):  # the --log line of one trial
            r = "-" if o.return_ is None else f"{o.return_:+.4f}"
            return (f"trial {p.index:4d}  round {p.round}  {p.step:14s} "
                    f"theta={np.round(p.theta, 4).tolist()} {'success' if o.success else 'FAILURE'}  R={r}")

        budget = getattr(getattr(session.learner, "optimizer", None), "max_evals", None)  # methods over w only
        with progress_tracker(f"run {method}", quiet=quiet, log=log, json_out=json_out) as tracker:
            def best():
                return None if session.best is None else session.best.return_

            def tick(p, o):
                tracker.update("trials", done=p.index + 1, total=budget, failures=int(not o.success), best=best(),
                               note=f"round {p.round} {p.step}", line=line(p, o))

            if session.history:  # resumed: what the store already holds
                tracker.update("trials", done=len(session.history), total=budget, best=best(), note="resumed",
                               failures=sum(not o.success for _, o in session.history))
            try:
                if info.config.get("robots", 1) > 1:
                    from corl.fleet import run_fleet

                    run_fleet(session, the_task, robots=info.config["robots"], backend=backend, callback=tick,
                              task_spec=info.task, seed=seed, address=address)
                else:
                    session.run(the_task, callback=tick)
                tracker.update("trials", done=len(session.history), total=len(session.history), note="finished")
            except TaskError as exc:  # says what the store keeps and the way on
                fail(str(exc))
            except CorlError as exc:
                fail(f"{exc} (the store {store_path} keeps every trial so far; resume with --resume)")
            payload = run_summary(the_task, method, seed, session.learner, time.perf_counter() - t0,
                                  context=info.config.get("context"), contextual=bool(info.config.get("contextual")))
            payload["store"] = str(store_path)
            payload["run_id"] = session.run_id
            if info.config.get("noise") is not None:  # corl.tasks.NoisyTask: the sensors the trials were read by
                payload["noise"] = info.config["noise"]
            if session.ended is not None:  # ended where the task's code raised (--end-at-error)
                payload["ended"] = session.ended
            payload.update(task_extras(the_task, session.learner))
            tracker.message("writing figures ...")
            payload["files"] = write_run_artifacts(the_task, session.learner, out)
    if video:  # after the store is closed and summary.json written: the run is safe whatever rendering does
        write_json(out / "summary.json", payload)
        if not quiet and not json_out:
            typer.echo("rendering the video ...", err=True)
        payload["files"].update(write_run_video(the_task, session.learner, out))
        if "video_skipped" in payload["files"]:  # asked for and not made: never exit 0 without it
            write_json(out / "summary.json", payload)
            fail(f"--video: no video ({payload['files']['video_skipped']}); the run's results are in {out} "
                 f"(summary.json, the store): render it later with corl report --store {store_path} --video")
    elif hasattr(the_task, "render_comparison"):
        payload["files"]["video_skipped"] = "not asked for; add --video (or render it later: corl report --video)"
    write_json(out / "summary.json", payload)
    if json_out:
        return print_json(payload)
    typer.echo(run_text(payload, out / "summary.json"))


def _rendering() -> tuple[bool, str]:
    """(True, "") when this machine renders offscreen, choosing MUJOCO_GL first when headless
    (:func:`corl.mujoco.video.ensure_rendering`), else (False, one line that says what to install)."""
    from corl.mujoco.video import ensure_rendering

    return ensure_rendering()


def ask(
    store: Path = typer.Option(..., help="run store"),
    task: str = typer.Option(..., help="the task: 'synthetic' or 'package.module:make_task'"),
    method: Optional[str] = typer.Option(None, help="method of a new run (default: CORL+PIBU for the built-in "
                                                    "tasks, CORL for yours, as corl run and corl serve); with a "
                                                    "run in the store, only that run's method is accepted"),
    seed: Optional[int] = typer.Option(None, help="seed of a new run (default 0); with a run in the store, only "
                                                  "that run's seed is accepted"),
    rate: float = typer.Option(100.0, help="rate of the written trajectory (Hz)"),
    out: Optional[Path] = typer.Option(None, help="folder for trial_<i>.csv/.npz (default: beside the store)"),
    raw: bool = typer.Option(False, "--raw", help="for a task without reference(): write the raw parameters w "
                                                 "(trial_<i>_raw_parameters.csv), NOT a joint trajectory"),
    context: Optional[str] = typer.Option(None, help="a new run in this scene (a task with contexts), learning from "
                                                     "the store's runs in other contexts: comma-separated numbers, "
                                                     "e.g. 0.02,-0.01,0,0.1; the same context continues its run"),
    p_min: Optional[str] = P_MIN_OPTION,
) -> None:
    """Write the next trial's trajectory (CSV and NPZ) and print its theta (real-robot loop)."""
    from corl.errors import CorlError
    from corl.methods import METHODS
    from corl.session import trajectory_of

    check_args(task=("--task", task), seed=("--seed", seed), rate=("--rate", rate), store=("--store", store),
               folder=("--out", out))
    if method is not None and method not in METHODS:
        fail(f"unknown method '{method}'; choose from {', '.join(METHODS)}")
    skill = skill_settings(p_min, context=context)
    NEW_PATHS.track(store, *([out] if out is not None else []))
    try:  # the trial is computed and checked before the store is opened for writing
        the_task, session, seen = _run_to_ask(task, store, method=method, seed=seed, raw=raw, rate=rate,
                                              context=context, skill=skill)
        proposal = session.learner.ask()
        trajectory = None if raw else trajectory_of(the_task, proposal.w, rate)
        with open_store(store) as db:
            if session.run_id is None:
                _refuse_new_runs(db, store, seen)
            session.attach(db).hand_out(proposal)
    except CorlError as exc:
        fail(str(exc))
    _write_trial(out or store.parent, the_task, proposal, trajectory, run_id=session.run_id,
                 context=getattr(the_task, "context", None) if getattr(the_task, "with_context", None) else None)


def _run_to_ask(task: str, store: Path, *, method, seed, raw: bool, rate: float, context, skill=None):
    """``(task in the run's scene, StoredRun, id of the store's latest run)`` of ``corl ask``: the store's
    latest run replayed read-only, or a new one (with ``--context``: in that scene, learning from the store)."""
    import numpy as np

    from corl.session import StoredRun, trajectory_of
    from corl.store import RunStatus
    from corl.tasks.registry import load_task

    info = latest_run(store)  # read-only
    unfinished = info is not None and info.status is not RunStatus.FINISHED
    c = None
    if context is not None:  # a new run in that scene, or the unfinished latest run when it is in that scene
        the_task = load_task(task, seed=int(info.seed or 0) if unfinished else seed or 0)
        c = parse_context(the_task, context)
        if unfinished:
            _refuse_other_scene(info, store, c)
    if info is not None and (context is None or unfinished):
        _refuse_other_flags(info, ("--method", method, info.method), ("--seed", seed, info.seed),
                            *_skill_flags(info, skill))
        if not unfinished:
            _refuse_finished(info, store)
    if context is None:
        the_task = load_task(task, seed=int(info.seed or 0) if info is not None else seed or 0)
    if getattr(the_task, "reference", None) is None and not raw:  # corl.problem.HasReference
        trajectory_of(the_task, np.zeros(1), rate)  # raises the message, before a trial is handed out
    if info is None or (c is not None and not unfinished):
        if c is None:
            return the_task, StoredRun.new(the_task, task_spec=task, method=method or _default_method(task),
                                           seed=seed or 0), None
        return scene_of(the_task, c), _new_in_context(the_task, task, store, method=method, seed=seed, context=c,
                                                      overrides=None, skill=skill), \
            info.id if info is not None else None
    session = _reopened(the_task, store, info)
    if session.done:
        _refuse_finished(info, store)
    return _run_scene(the_task, info), session, info.id


def _run_scene(the_task, info):
    """The task in the scene of stored run ``info``: its context when it learned in one, else the task."""
    return scene_of(the_task, recorded_context(info)) if info.config.get("contextual") else the_task


def _new_in_context(the_task, task_spec: str, store: Path, *, method, seed, context, overrides, skill=None):
    """A new run in scene ``context`` that learns from the store's runs (the store opened read-only);
    ``skill``: the skill's settings (:func:`corl.cli.skill.skill_settings`)."""
    from corl.session import StoredRun

    new = dict(task_spec=task_spec, method=method or "CORL", seed=seed or 0, corl_overrides=overrides,
               context=context, skill=skill)
    if latest_run(store) is None:  # no store, or no run in it yet: nothing learned, the demonstration
        return StoredRun.new(the_task, learned_from=None, **new)
    with open_store(store, readonly=True) as db:
        return StoredRun.new(the_task, learned_from=db, **new)


def _refuse_new_runs(db, store: Path, seen) -> None:
    """Exit 2 when another process added a run since ``seen`` (the latest run id read, or None) was read:
    what a new run learned from, or the run it would have continued, is no longer the store's latest."""
    latest = db.latest_run()
    if (latest.id if latest is not None else None) != seen:
        fail(f"another process started a run in {store} meanwhile; nothing was written: run the command again")


def _refuse_other_scene(info, store: Path, c, *, resume_hint: bool = False) -> None:
    """``corl ask --context C`` (or ``corl run --context C`` without ``--resume``) while the store's latest
    run is unfinished: only in scene C does ``ask`` go on; ``run`` continues it with ``--resume``."""
    import numpy as np

    rc = recorded_context(info)
    if rc is not None and rc.shape == c.shape and np.array_equal(rc, c):
        if not resume_hint:
            return
        fail(f"run {info.id} in {store} is in context {context_text(c)} and not finished: continue it with "
             "corl run --resume (a new run would leave it, and any trial pending on the robot, behind)")
    where = "no context" if rc is None else f"context {context_text(rc)}"
    pending = info.n_trials > info.n_told
    state, first = (", a trial is pending", "corl tell its pending trial, then ") if pending else ("", "")
    fail(f"run {info.id} in {store} (task '{info.task}', {where}) is not finished{state}, so no run in context "
         f"{context_text(c)} can start there: finish it first ({first}corl ask without --context until it is "
         "done), or use another --store")


def _write_trial(folder: Path, the_task, proposal, trajectory, *, run_id=None, context=None) -> None:
    """Write the handed-out trial (trajectory CSV/NPZ, or the raw w) and print where it went; the NPZ and
    the printed line name the run and, for a task with contexts, the scene it is for."""
    import numpy as np

    from corl.experiments.sweep import write_raw_parameters

    try:
        if trajectory is None:
            return typer.echo(json.dumps(write_raw_parameters(proposal, folder)))
        t, q = trajectory
        folder.mkdir(parents=True, exist_ok=True)
        stem = folder / f"trial_{proposal.index:04d}"
        scene = {} if context is None else {"context": np.asarray(context, dtype=float)}
        np.savez(stem.with_suffix(".npz"), t=t, q=q, w=proposal.w, theta=proposal.theta,
                 run=np.array(-1 if run_id is None else run_id), **scene)
        names = getattr(the_task, "joint_names", None) or [f"q{j}" for j in range(q.shape[1])]
        np.savetxt(stem.with_suffix(".csv"), np.column_stack([t, q]), delimiter=",", header="t," + ",".join(names),
                   comments="")
    except OSError as exc:
        fail(f"cannot write trial {proposal.index} to {folder}: {exc.strerror}; the trial is stored as pending: "
             "free space (or give another --out) and run 'corl ask' again to write it")
    scene = {} if context is None else {"context": np.asarray(context, dtype=float).tolist()}
    typer.echo(json.dumps({"trial": proposal.index, "run": run_id, **scene, "step": proposal.step,
                           "round": proposal.round, "theta": proposal.theta.tolist(),
                           "csv": str(stem.with_suffix(".csv")), "npz": str(stem.with_suffix(".npz"))}))


def tell(
    store: Path = typer.Option(..., help="run store"),
    task: str = typer.Option(..., help="the task: 'synthetic' or 'package.module:make_task'"),
    success: str = typer.Option(..., help="did the trial succeed: yes or no"),
    return_: Optional[str] = typer.Option(None, "--return", help="the measured return (needed on success), a plain "
                                                                 "number such as 0.25 or -1.5e3"),
) -> None:
    """Record the outcome of the pending trial."""
    from corl.errors import CorlError
    from corl.problem import Outcome

    flag = success.strip().lower()
    if flag not in ("yes", "no"):
        fail(f"--success must be yes or no, got {success!r}")
    check_args(task=("--task", task), store=("--store", store))
    if flag == "no" and return_ is not None:
        fail(f"a failed trial is told without a return: drop --return {return_} (or say --success yes if the "
             "trial succeeded); nothing was stored")
    try:
        outcome = Outcome(flag == "yes", None if return_ is None else plain_number("--return", return_))
        session = _run_to_tell(task, store, outcome)  # every check before the store is opened for writing
        with open_store(store, create=False) as db:
            session.attach(db).tell(outcome)
    except CorlError as exc:
        fail(str(exc))
    typer.echo(json.dumps({"trial": len(session.history) - 1, "success": outcome.success,
                           "return": outcome.return_, "done": session.done}))


def _run_to_tell(task: str, store: Path, outcome):
    """The StoredRun whose pending trial ``outcome`` answers, replayed read-only and checked (StoredRun.check)."""
    from corl.session import StoredRun
    from corl.tasks.registry import load_task

    with open_store(store, readonly=True) as db:
        info = db.latest_run()
        if info is None:
            fail(f"{store} holds no run; start one with 'corl ask'")
        if db.pending(info.id) is None:
            fail("there is no pending trial to tell (each trial is told once): run 'corl ask' first")
        session = StoredRun.open(db, load_task(task, seed=int(info.seed or 0)), info.id)
        session.check(outcome)
    return session


def _sensor_flags(return_noise: str | None, flip: str | None) -> dict[str, float]:
    """``--return-noise`` and ``--flip`` as ``{"return_noise": ..., "flip": ...}`` (only those given), checked."""
    from corl.tasks.noisy import check_flip, check_return_noise

    given = {}
    if return_noise is not None:
        given["return_noise"] = check_return_noise(plain_number("--return-noise", return_noise), "--return-noise")
    if flip is not None:
        given["flip"] = check_flip(plain_number("--flip", flip), "--flip")
    return given


def _with_sensors(the_task, sensors: dict | None, seed: int):
    """``the_task`` seen through the sensors ``{"return_noise", "flip"[, "seed"]}`` (corl.tasks.NoisyTask), or
    as it is when there are none."""
    from corl.tasks.noisy import NoisyTask

    if not sensors:
        return the_task
    return NoisyTask(the_task, return_noise=sensors.get("return_noise", 0.0), flip=sensors.get("flip", 0.0),
                     seed=sensors.get("seed", seed))


def _run_to_continue(task: str, store_path: Path, *, resume: bool, method, seed, rollout_every_step, quiet: bool,
                     context=None, sensors: dict | None = None, end_at_error: bool = False, skill=None,
                     robots: int | None = None):
    """``(task in the run's scene, StoredRun, seen)`` of ``corl run``: the store's latest run replayed from a
    read-only open (``--resume``), or a new run in no store yet; nothing is written (see StoredRun.attach).
    ``seen``: for a new run in a context, ``(id of the latest run it learned up to,)``; else None.
    ``sensors`` (``--return-noise``, ``--flip``): a new run's task is seen through them; a resumed run keeps
    its recorded ones, and a flag given with another value is refused. ``end_at_error``: see StoredRun.open."""
    from corl.session import StoredRun
    from corl.store import RunStatus
    from corl.tasks.registry import load_task

    sensors = sensors or {}
    info = latest_run(store_path) if resume else None  # read-only
    if resume and info is None and not quiet:
        typer.echo(f"--resume: {store_path} holds no run yet (killed before its first commit?); starting one", err=True)
    if info is None:
        seed = 0 if seed is None else seed
        the_task = _with_sensors(load_task(task, seed=seed), sensors, seed)
        overrides = None if rollout_every_step is None else {"rollout_every_step": rollout_every_step}
        if context is not None:
            c = parse_context(the_task, context)
            latest = latest_run(store_path)
            if latest is not None and latest.status is not RunStatus.FINISHED:  # its robot trial would be orphaned
                _refuse_other_scene(latest, store_path, c, resume_hint=True)
            return scene_of(the_task, c), _new_in_context(the_task, task, store_path, method=method, seed=seed,
                                                          context=c, overrides=overrides, skill=skill), \
                (latest and latest.id,)
        method = method or ("CORL" if (robots or 1) > 1 else _default_method(task))  # SEIB keeps K apart
        return the_task, StoredRun.new(the_task, task_spec=task, method=method, seed=seed,
                                       corl_overrides=overrides, robots=robots or 1), None
    stored_every = info.config.get("corl_overrides", {}).get("rollout_every_step")
    stored_sensors = info.config.get("noise") or {}  # a run without sensors reads exactly: 0 and 0
    _refuse_other_flags(info, ("--method", method, info.method), ("--seed", seed, info.seed),
                        ("--[no-]rollout-every-step", rollout_every_step, stored_every),
                        ("--robots", robots, info.config.get("robots", 1)),
                        *((f"--{k.replace('_', '-')}", v, stored_sensors.get(k, 0.0)) for k, v in sensors.items()),
                        *_skill_flags(info, skill))
    the_task = _with_sensors(load_task(task, seed=int(info.seed or 0)), stored_sensors, int(info.seed or 0))
    if context is not None:
        _refuse_other_context(info, store_path, parse_context(the_task, context))
    return _run_scene(the_task, info), _reopened(the_task, store_path, info, end_at_error=end_at_error), None


def _refuse_other_context(info, store: Path, c) -> None:
    """``corl run --context C --resume``: the latest run goes on only when it learned in scene C."""
    import numpy as np

    rc = recorded_context(info)
    if rc is not None and rc.shape == c.shape and np.array_equal(rc, c):
        return
    where, same = (("no context", "drop --context") if rc is None
                   else (f"context {context_text(rc)}", f"give --context {context_text(rc)}"))
    fail(f"--resume continues run {info.id} in {store}, which learned in {where}, not in --context "
         f"{context_text(c)}: drop --resume to start a new run in context {context_text(c)}, or {same} to "
         f"continue run {info.id}")


def _reopened(the_task, store_path: Path, info, *, end_at_error: bool = False):
    """The StoredRun of run ``info``: its trials replayed into a fresh learner, the store opened read-only."""
    from corl.session import StoredRun

    with open_store(store_path, readonly=True) as db:
        return StoredRun.open(db, the_task, info.id, end_at_error=end_at_error)


def _refuse_other_flags(info, *flags: tuple[str, object, object]) -> None:
    """Exit 2 when a ``(flag, given, stored)`` was given with another value than the stored run's."""
    for flag, given, stored in flags:
        if given is not None and given != stored:
            fail(f"{flag} {given} differs from the run being resumed (run {info.id} has {stored}); drop the "
                 "flag, or give another --store to start a new run")


def _skill_flags(info, skill: dict | None):
    """``(flag, given, stored)`` of each skill setting given, against the stored run's (for _refuse_other_flags)."""
    from corl.contexts.skill import P_MIN

    stored = {"p_min": P_MIN, **(info.config.get("skill") or {})}
    return [(f"--{k.replace('_', '-')}", v, stored.get(k)) for k, v in (skill or {}).items()]


def _refuse_finished(info, store: Path) -> None:
    fail(f"run {info.id} in {store} has finished, so there is no next trial to ask; 'corl report --store {store} "
         "--out DIR' (or 'corl status') shows its result, and another --store starts a new run")


def _default_method(task_spec: str) -> str:
    """The method a new run gets when none is named, the same for ``corl run``, ``corl ask`` and ``corl serve``:
    the paper's CORL+PIBU on a built-in task (its figures), corl's CORL on a user's."""
    from corl.methods import DEFAULT_METHOD
    from corl.tasks.registry import BUILTIN_TASKS

    return "CORL+PIBU" if task_spec in BUILTIN_TASKS else DEFAULT_METHOD
