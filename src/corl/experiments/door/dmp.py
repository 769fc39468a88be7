"""DMP+PoWER on the door (Sec. VIII-B): the paper's baseline without CORL's structure.

A DMP (``DMP_BASIS`` bases per dimension, 8 dimensions: 96 shape and goal parameters) is fitted to
the demonstration's reference; PoWER searches its parameters in a box of ``DMP_BOX_SCALES``
parameter scales around the fit. Trial 0 is the fitted DMP, then ``iterations`` PoWER trials.
Each trial's theta is measured on the executed reference (a B-spline fit of it, then
``task.theta_of``).
"""

from __future__ import annotations

import math
import time

import numpy as np

from corl.experiments.door.runs import DoorRun, door_task, true_return

__all__ = ["DMP_BASIS", "DMP_BOX_SCALES", "DMP_POWER_STD", "DMP_OVERLAP", "run_dmp_power"]

DMP_BASIS = 11            # basis functions per dimension: 8 (11 + 1) = 96 parameters (Sec. VIII-B)
DMP_BOX_SCALES = 3.0      # PoWER's box: fitted params +- this many param_scale units
DMP_POWER_STD = 0.005     # PoWER's exploration std as a fraction of the box width (0.03 param scales);
                          # the best of 0.0025, 0.005, 0.01, 0.02 on seed 0 over 40 trials (0.02: 38 failures)
DMP_OVERLAP = 0.8         # neighbouring bases cross at 0.8: with 0.5 the 11-basis fit of the demonstration
                          # grasps too wide (the gripper width 5 mm off at t_c) and fails in the simulator


def _dmp_trial(task, dmp, params):
    """Roll out the DMP with ``params`` (96,): its Outcome (R as the door task's) and measured theta."""
    from corl.problem import Outcome
    from corl.tasks.door.demo import CONTROL_DT
    from corl.tasks.door.sim import rollout
    from corl.tasks.door.task import grasp_instant, return_of_force

    t, Y = dmp.reference(params, dt=CONTROL_DT, duration=task.duration)
    if not np.all(np.isfinite(Y)):
        return Outcome(False, None, {"diverged": True}), np.full(2, np.nan)
    theta = task.theta_of(task.spline.fit(t, Y))  # theta of the executed reference (B-spline fit)
    result = rollout(Y, duration=task.duration, t_contact=grasp_instant(t, Y), scene=task.scene)
    if not result.success:
        return Outcome(False, None), theta
    force = task.measured_force(result.force_mean, params)  # the same sensor (and error) as CORL's trials
    return Outcome(True, return_of_force(force), {"force_mean": result.force_mean}), theta


def run_dmp_power(seed: int, iterations: int = 150, *, task=None, box_scales: float = DMP_BOX_SCALES,
                  std: float = DMP_POWER_STD) -> DoorRun:
    """The paper's baseline: PoWER over the 96 shape and goal parameters of a fitted DMP.

    Trial 0 is the DMP fitted to the demonstration's reference (the PoWER mean's start); then
    ``iterations`` PoWER trials in the box ``params +- box_scales * param_scale`` with exploration
    ``std`` (a fraction of the box width). Failures score the task's ``failure_return``.
    """
    from corl.optimizers.power import PoWER, PoWERConfig
    from corl.policies.dmp import DMP, DMPConfig
    from corl.problem import Bounds

    t0 = time.perf_counter()
    task = task or door_task({})
    demo = task.demonstration()
    times, Y = task.reference(demo.w)
    dmp = DMP.fit(times, Y, n_basis=DMP_BASIS, config=DMPConfig(overlap=DMP_OVERLAP))
    x0, scale = dmp.params, dmp.param_scale
    bounds = Bounds(x0 - box_scales * scale, x0 + box_scales * scale)
    optimizer = PoWER(bounds, x0, PoWERConfig(std=std), failure_return=task.method_settings().failure_return,
                      max_evals=iterations + 1, seed=np.random.default_rng([seed, 96]))
    fails, success, returns = [], [], []
    start_return = first_return = math.nan
    best = (-math.inf, None, math.nan)  # measured R, theta, true R of the best success (the fit included)
    for k in range(iterations + 1):
        params = x0 if k == 0 else optimizer.ask()
        outcome, theta = _dmp_trial(task, dmp, params)
        optimizer.tell(params, outcome)
        r = float(outcome.return_) if outcome.success else math.nan
        if outcome.success and r > best[0]:
            best = (r, theta, true_return(outcome))
        if k == 0:
            start_return = r
            continue
        if k == 1:
            first_return = r
        success.append(outcome.success)
        returns.append(r)
        if not outcome.success:
            fails.append(theta)
    return DoorRun(
        method="DMP+PoWER", seed=seed, trials=iterations, failures=len(fails), unrealisable=0,
        highest_return=best[0] if best[1] is not None else math.nan, start_return=start_return,
        first_return=first_return, failed_thetas=np.array(fails, dtype=float).reshape(-1, 2),
        trial_success=np.array(success, dtype=bool), trial_returns=np.array(returns, dtype=float),
        final_return=best[2], best_theta=best[1],
        anchor=np.asarray(demo.w, dtype=float), anchor_times=tuple(task.contact_times.tolist()),
        rollouts=iterations + 1, seconds=time.perf_counter() - t0)
