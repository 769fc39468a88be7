"""The door's motion optimization (Alg. 1, step 1, Eq. 8; and Eq. 18) before and after the SQP path.

    python benchmarks/door_motion.py [--steps 10] [--repeats 5]

Problem: the PR2 door of Sec. VIII-B (:class:`corl.tasks.door.task.DoorTask`, n = 1200): J the
squared joint accelerations (Eq. 9), h the contact constraints at theta0 (Eq. 6). Step 1 is the
learner's chain of trust-region steps from the demonstration, ``w(i+1) = argmin J s.t. h = 0,
||w - w(i)|| <= eps_max`` with the door's eps_max = 0.1, ``--steps`` of them, no rollouts.

* before: what Algorithm 1 ran until the task gave its structure: a
  :class:`~corl.trajectory.solver.FunctionProblem` of ``cost_residuals`` and ``projection``
  (no ``affine_cost``), hence the augmented Lagrangian (``SolverConfig(method="al")``).
* after: the task's ``trajectory_problem(theta0)`` with ``SolverConfig()``: SQP / Newton-KKT
  steps on the banded Hessian (:mod:`corl.trajectory.solver.sqp`), the augmented Lagrangian as fallback.

The Eq. 18 rows realise one theta away from theta0 (the grasp 3 cm further along the handle,
the fingers 2 mm wider) from the demonstration, in the door's acceleration metric, the same
way: a FunctionProblem with ``L (w - w*)`` residuals solved by the augmented Lagrangian before,
the task's problem with the cost swapped for the distance (SQP) after.

The SQP path's Newton-KKT steps take the constraint curvature ``sum_i lam_i d2h_i`` from the
kit's features (:mod:`corl.mujoco.features`, picked up by ``TaskSpaceFeature``): exact second
derivatives formed from the Jacobians of the one ``mj_kinematics`` per configuration that gave
value and Jacobian, cached per configuration. (Until they had them: forward differences of the
Jacobian, 8 more forward kinematics per contact time and curvature call, which made Eq. 18 on SQP
slower than the augmented Lagrangian.) The augmented Lagrangian's FunctionProblem uses none.

The cases run interleaved ``--repeats`` times; the table gives the fastest run (the one the
machine's other load disturbed least) and the median, per step of the chain. The task (MuJoCo
scene, demonstration) is built once, outside the timing; each run gets fresh constraint features
(``task.retimed`` to the same times, untimed), so no run reads the feature caches of the last one.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import replace

os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402

from corl.tasks.door.task import EPS_MAX, DoorTask  # noqa: E402
from corl.versions import library_versions  # noqa: E402
from corl.trajectory.solver import FunctionProblem, SolverConfig, SolverMethod, project, solve  # noqa: E402

SQP = SolverConfig()
AL = replace(SQP, method=SolverMethod.AUGMENTED_LAGRANGIAN)


def step_one(problem, w0: np.ndarray, config: SolverConfig, steps: int):
    """Alg. 1, step 1 without rollouts: ``steps`` trust-region solves, each centred on the last."""
    w, iterations, statuses = w0, [], []
    for _ in range(steps):
        result = solve(problem, w, center=w, radius=EPS_MAX, config=config)
        iterations.append(result.iterations)
        statuses.append(result.converged)
        w = result.w
    return w, iterations, statuses


def timed(cases, repeats: int, fresh):
    """Run the ``(name, fn)`` cases interleaved ``repeats`` times (so a change of the machine's load hits
    all of them alike), each as ``fn(fresh())`` with only ``fn`` timed; per case the fastest time (the
    least disturbed), the median and the last result."""
    times: dict = {name: [] for name, _ in cases}
    out: dict = {}
    for _ in range(repeats):
        for name, fn in cases:
            task = fresh()
            t0 = time.perf_counter()
            out[name] = fn(task)
            times[name].append(time.perf_counter() - t0)
    return {name: (min(t), statistics.median(t), out[name]) for name, t in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=10, help="trust-region steps of step 1")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    task = DoorTask()
    demo = task.demonstration()
    w0, theta0 = demo.w, demo.theta
    theta = theta0 + np.array([0.03, 0.002])  # Eq. 18's target

    def fresh() -> DoorTask:
        """The task with new constraint features (the same times), built for theta0 and theta."""
        copy = task.retimed(lambda times: times)
        copy.trajectory_problem(theta0), copy.trajectory_problem(theta)
        return copy

    J = lambda w: float(np.dot(task.cost_residuals(w)[0], task.cost_residuals(w)[0]))  # noqa: E731
    h_max = lambda w, th: float(np.abs(task.constraint(w, th)[0]).max())  # noqa: E731
    print("versions: " + ", ".join(f"{k} {v}" for k, v in library_versions().items()))
    print(f"door: n = {w0.shape[0]}, q = {task.constraint(w0, theta0)[0].shape[0]}, eps_max = {EPS_MAX}, "
          f"J(w0) = {J(w0):.1f}, {args.steps} steps of Eq. 8, best and median of {args.repeats}")
    print()
    header = (f"{'':34s} {'ms/step':>9s} {'(median)':>9s} {'iter/step':>10s} {'converged':>10s} {'final J':>10s} "
              f"{'max|h|':>9s}")
    print(header)
    print("-" * len(header))
    before = lambda t: FunctionProblem(t.cost_residuals, lambda w: t.constraint(w, theta0))  # noqa: E731
    steps = [(name, lambda t, problem=problem, config=config: step_one(problem(t), w0, config, args.steps))
             for name, problem, config in (("step 1, before (augmented Lagr.)", before, AL),
                                           ("step 1, after (SQP, banded KKT)", lambda t: t.trajectory_problem(theta0), SQP))]
    rows = {}
    for name, (best, median, (w, iters, ok)) in timed(steps, args.repeats, fresh).items():
        rows[name] = w
        print(f"{name:34s} {1e3 * best / args.steps:9.1f} {1e3 * median / args.steps:9.1f} {np.mean(iters):10.1f} "
              f"{sum(ok):>5d}/{len(ok):<4d} {J(w):10.2f} {h_max(w, theta0):9.1e}")
    L = task.projection_metric
    cases = [("Eq. 18, before (augmented Lagr.)",
              lambda t: solve(FunctionProblem(lambda w: (L @ (w - w0), L), lambda w: t.constraint(w, theta)), w0,
                              config=AL)),
             ("Eq. 18, after (SQP, banded KKT)",
              lambda t: project(t.trajectory_problem(theta), w0, metric=L, config=SQP))]
    for name, (best, median, result) in timed(cases, args.repeats, fresh).items():
        print(f"{name:34s} {1e3 * best:9.1f} {1e3 * median:9.1f} {result.iterations:10d} {str(result.converged):>10s} "
              f"{J(result.w):10.2f} {h_max(result.w, theta):9.1e}")
    w_al, w_sqp = rows.values()
    print()
    print(f"||w_SQP - w_AL|| after step 1: {np.linalg.norm(w_sqp - w_al):.2e} (||w0|| = {np.linalg.norm(w0):.1f})")


if __name__ == "__main__":
    main()
