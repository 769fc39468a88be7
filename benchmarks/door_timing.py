"""Where a door run's time goes, beside its floors.

    python benchmarks/door_timing.py [--seed 0] [--video] [--json PATH]

Runs what ``corl run door --seed 0`` runs (CORL+PIBU, every trial committed to a run store in a
temporary folder) twice: as ``corl run`` runs it (rollouts in a forked worker while CORL computes its
next motion step), for the wall time; then in one process with a timer around each part of
Algorithm 1, for one table:

* motion optimization by step kind: step 1's trust-region solves (Eq. 8), the phase steps
  (Eq. 10, ``optimize_phase``), re-timing with its Eq. 18 projection (``retime``), and Eq. 18 for
  each black-box proposal (``realise``);
* rollouts (``DoorTask.rollout``: the MuJoCo trial and its measurements);
* GP fits (``GPRegression.fit``, ``GPClassifier.fit``) and the acquisition (the black-box
  optimizer's decision of the next theta, ``_propose``, minus the fits inside it);
* the store (``add_proposal``, ``add_outcome``, ``set_status``);
* the rest (the learner's own bookkeeping, J evaluations, ...);
* with ``--video``: ``render_comparison`` after learning, as ``corl run --video`` does.

Each part's time is exclusive: a timed call inside another (a GP fit inside ``_propose``) counts for the
inner part only. The floors, measured in the same run:

* MuJoCo stepping alone: ``mj_step`` on the door model for as many steps as the rollouts took,
  from the demonstration's start, with the servo set-points held (no Python between steps but the loop);
* one banded factorisation per Newton iteration: the iterations every motion solve reported,
  times one ``dpbtrf`` of the door's KKT Hessian band (n = 1200, ``H_J + 2 mu Jh^T Jh``).

``OPENBLAS_NUM_THREADS=1`` is set before numpy is imported, as ``make`` does.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402


class Timers:
    """Exclusive wall time and call counts per part: a stack of the parts running now."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self.iterations = 0  # Newton / Gauss-Newton iterations the motion solves reported
        self._stack: list[list] = []  # [part, start, time spent in timed callees]

    def wrap(self, owner, name: str, part: str) -> None:
        """Replace ``owner.name`` by a timed call counted for ``part``."""
        fn = getattr(owner, name)
        timers = self

        def timed(*args, **kwargs):
            frame = [part, time.perf_counter(), 0.0]
            timers._stack.append(frame)
            try:
                return fn(*args, **kwargs)
            finally:
                timers._stack.pop()
                total = time.perf_counter() - frame[1]
                timers.seconds[part] += total - frame[2]
                timers.calls[part] += 1
                if timers._stack:
                    timers._stack[-1][2] += total

        setattr(owner, name, timed)

    def count_iterations(self, owner, name: str) -> None:
        """Add the ``iterations`` of every result ``owner.name`` returns (a motion solve)."""
        fn = getattr(owner, name)
        timers = self

        def counted(*args, **kwargs):
            result = fn(*args, **kwargs)
            timers.iterations += int(getattr(result, "iterations", 0) or 0)
            return result

        setattr(owner, name, counted)


def instrument(timers: Timers) -> None:
    """Time the parts of Algorithm 1 where the learner looks them up (module attributes)."""
    import corl.learner as learner
    import corl.optimizers.bo as bo
    import corl.realise as realise
    import corl.trajectory.phase as phase
    from corl.gp.classification import GPClassifier
    from corl.gp.regression import GPRegression
    from corl.store.sqlite import RunStore
    from corl.tasks.door.task import DoorTask

    for module in (learner, realise, phase):  # every motion solve, for the iteration count
        for name in ("solve", "project"):
            if hasattr(module, name):
                timers.count_iterations(module, name)
    timers.wrap(learner, "solve", "motion: step 1 (Eq. 8)")
    timers.wrap(phase, "optimize_phase", "motion: phase steps (Eq. 10)")
    timers.wrap(phase, "retime", "motion: re-time + Eq. 18")
    timers.wrap(learner, "realise", "motion: Eq. 18 per proposal")
    timers.wrap(DoorTask, "rollout", "rollouts (MuJoCo + measurements)")
    timers.wrap(GPRegression, "fit", "GP fits")
    timers.wrap(GPClassifier, "fit", "GP fits")
    import corl.optimizers.safe as safe

    for module in (bo, safe):  # the decision of the next theta (made when ``done`` is read)
        for cls in vars(module).values():
            if isinstance(cls, type) and "_propose" in vars(cls):
                timers.wrap(cls, "_propose", "acquisition (without fits)")
    for name in ("add_proposal", "add_outcome", "set_status", "create_run"):
        timers.wrap(RunStore, name, "store")


def learn(seed: int, folder: Path, *, worker: bool):
    """``corl run door --seed SEED`` without the CLI: a run store in ``folder``; returns the session.

    ``worker``: as ``corl run`` does, roll out in a forked process while CORL computes its next step
    (:mod:`corl.tasks.worker`); False: everything in this process, one part after the other (the
    timers see only this process, so the table's parts come from a run with ``worker=False``).
    """
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.registry import load_task

    task = load_task("door", seed=seed)
    session = StoredRun.new(task, task_spec="door", method="CORL+PIBU", seed=seed)
    with RunStore(folder / "run.corl") as db:
        session.attach(db)
        session.run(task, worker=worker)
    return task, session


def warm_up() -> None:
    """Import and call once what both timed runs use (a short CORL run on the door, 3 trials)."""
    from corl.session import StoredRun
    from corl.store import RunStore
    from corl.tasks.registry import load_task

    task = load_task("door")
    with tempfile.TemporaryDirectory() as tmp, RunStore(Path(tmp) / "run.corl") as db:
        session = StoredRun.new(task, task_spec="door", method="CORL+PIBU", seed=0).attach(db)
        session.run(task, max_trials=3, worker=False)


def mujoco_floor(steps: int) -> float:
    """Seconds of ``steps`` bare ``mj_step`` calls on the door model from the demonstration's start."""
    import mujoco

    from corl.tasks.door.task import DoorTask

    task = DoorTask()
    model = task.scene.model
    data = mujoco.MjData(model)
    _, q = task.reference(task.demonstration().w)
    task.scene.robot.write(data, q[0])
    mujoco.mj_forward(model, data)
    per_trial = min(steps, 2500)
    t0 = time.perf_counter()
    done = 0
    while done < steps:
        mujoco.mj_resetData(model, data)
        task.scene.robot.write(data, q[0])
        for _ in range(min(per_trial, steps - done)):
            mujoco.mj_step(model, data)
        done += per_trial
    return time.perf_counter() - t0


def factorisation_floor(repeats: int = 200) -> tuple[float, int, int]:
    """(seconds of one ``dpbtrf`` of the door's KKT Hessian band, n, bandwidth): the median of ``repeats``.

    The matrix is the one the SQP factorises at the demonstration: ``H_J + 2 mu Jh^T Jh`` (mu as the
    SQP's first, the scale of H_J over that of the Gram matrix), in band storage. (``H_J`` alone
    factorises about 3x faster: its band has more zeros, which the BLAS kernel skips.)
    """
    from scipy.linalg.lapack import dpbtrf

    from corl.tasks.door.task import DoorTask

    task = DoorTask()
    demo = task.demonstration()
    problem = task.trajectory_problem(demo.theta)
    H, _ = problem.affine_cost()
    _, Jh = problem.equalities(demo.w)
    G = np.asarray((Jh.T @ Jh).todense())  # (n, n), inside the band of H_J (Eq. 6 at one time each)
    u = H.ab.shape[0] - 1
    n = H.ab.shape[1]
    rows = np.arange(n)
    gram_band = np.zeros_like(H.ab)
    for k in range(u + 1):  # lower band storage: ab[k, j] = M[j + k, j]
        gram_band[k, : n - k] = G[rows[: n - k] + k, rows[: n - k]]
    outside = float(np.abs(G).sum() - np.abs(np.diag(G)).sum() - 2.0 * np.abs(gram_band[1:]).sum())
    if outside > 1e-9 * float(np.abs(G).sum()):
        raise RuntimeError("the constraint Gram matrix leaves the cost's band: widen the floor's band")
    mu = float(np.max(H.ab[0])) / float(np.max(np.diag(G)))
    ab = np.asfortranarray(H.ab + 2.0 * mu * gram_band)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _, info = dpbtrf(ab, lower=1)
        times.append(time.perf_counter() - t0)
        if info != 0:
            raise RuntimeError(f"dpbtrf failed (info {info})")
    return float(np.median(times)), n, u


def render_video(task, session, folder: Path) -> float:
    """Seconds of ``render_comparison`` (demonstration beside the best motion), as ``corl run --video``."""
    t0 = time.perf_counter()
    task.render_comparison(session.history[0][0].w, session.best.w, folder / "demo_vs_learned.mp4")
    return time.perf_counter() - t0


def table(timers: Timers, learning: float, steps: int, floors: dict, video: float | None) -> list[str]:
    rows = sorted(timers.seconds.items(), key=lambda kv: -kv[1])
    accounted = sum(timers.seconds.values())
    lines = [f"| part | calls | s | share of learning | floor (same run) |", "|---|---:|---:|---:|---|"]
    for part, sec in rows:
        floor = ""
        if part.startswith("rollouts"):
            floor = f"MuJoCo stepping alone, {steps} steps: {floors['mujoco']:.2f} s ({sec / floors['mujoco']:.1f}x)"
        lines.append(f"| {part} | {timers.calls[part]} | {sec:.2f} | {sec / learning:.0%} | {floor} |")
    motion = sum(v for k, v in timers.seconds.items() if k.startswith("motion"))
    fact = floors["factorisation"] * timers.iterations
    lines.append(f"| motion optimization, all | | {motion:.2f} | {motion / learning:.0%} | one banded factorisation "
                 f"per Newton iteration: {timers.iterations} x {floors['factorisation'] * 1e3:.3f} ms = {fact:.2f} s "
                 f"({motion / fact:.0f}x) |")
    lines.append(f"| the rest (learner, J, callbacks) | | {learning - accounted:.2f} | "
                 f"{(learning - accounted) / learning:.0%} | |")
    lines.append(f"| **learning, total** | | **{learning:.2f}** | 100% | |")
    if video is not None:
        lines.append(f"| video after learning (render_comparison) | 1 | {video:.2f} | | |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--video", action="store_true", help="also time the video corl run --video renders")
    parser.add_argument("--json", type=Path, help="write the numbers here too")
    args = parser.parse_args()
    from corl.versions import library_versions

    warm_up()  # imports and first-call costs land in neither timed run
    with tempfile.TemporaryDirectory() as tmp:  # first as corl run runs it, uninstrumented
        t0 = time.perf_counter()
        _, overlapped_session = learn(args.seed, Path(tmp), worker=True)
        overlapped = time.perf_counter() - t0
    timers = Timers()
    instrument(timers)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        task, session = learn(args.seed, Path(tmp), worker=False)
        learning = time.perf_counter() - t0
        video = render_video(task, session, Path(tmp)) if args.video else None
    same = all(np.array_equal(p.w, q.w) and o.success == r.success and o.return_ == r.return_
               for (p, o), (q, r) in zip(session.history, overlapped_session.history))
    same = same and len(session.history) == len(overlapped_session.history)
    history = session.history
    steps = timers.calls["rollouts (MuJoCo + measurements)"] * 2501  # 5 s at 500 Hz, both ends
    floors = {"mujoco": mujoco_floor(steps)}
    floors["factorisation"], n, u = factorisation_floor()
    best = session.best
    print(f"corl run door --seed {args.seed}: {len(history)} trials, {sum(not o.success for _, o in history)} "
          f"failures, best return {best.return_:+.4f}, J {best.J:.4g}; learning {learning:.2f} s "
          f"(task and demonstration included)")
    print(f"banded Hessian: n = {n}, bandwidth {u}")
    print("versions: " + ", ".join(f"{k} {v}" for k, v in library_versions().items()))
    print()
    print("\n".join(table(timers, learning, steps, floors, video)))
    print()
    print(f"as corl run runs it (rollouts in a worker process, the next motion step computed meanwhile): "
          f"{overlapped:.2f} s, against {learning:.2f} s in one process; the same trials: {same}")
    if args.json:
        args.json.write_text(json.dumps({"learning": learning, "overlapped": overlapped, "parts": dict(timers.seconds),
                                         "calls": dict(timers.calls), "iterations": timers.iterations,
                                         "floors": floors, "video": video, "trials": len(history),
                                         "versions": library_versions()}, indent=1))


if __name__ == "__main__":
    sys.exit(main())
