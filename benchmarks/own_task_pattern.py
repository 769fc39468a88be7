"""Does the own-task guide's pattern hold on a task whose success depends on the motion between its
constrained instants? (issue 33, item 4)

A task written from docs/guide/own-task.md alone: a planar 3-link arm presses a hinged flap and
holds it. ``theta`` is where along the flap the fingertip lands (m). The trial succeeds when the
fingertip lands on the flap and does not slip along it while pressing: between the touch
(t = 1.0 s) and the release (t = 2.0 s) it stays within 4 mm of where it landed. The return
rewards landing near 1.5 cm from the flap's centre (unknown to corl).

Three ways to write ``h``:

* ``guide``    the own-task guide's pattern: the fingertip constrained at the touch and the release,
               no ``projection_metric`` (Eq. 18 in the plain distance ``|w - w*|``);
* ``metric``   the same two instants, plus ``projection_metric = [A / 100; 0.1 I]`` (A: the
               accelerations), the own-robot guide's metric;
* ``interval`` the fingertip constrained every 0.05 s over the whole press (21 instants, closer than
               the spline's knots, 0.089 s apart), no metric: the own-task guide's advice now.

Run:  python benchmarks/own_task_pattern.py [--seeds 3]   (about a minute on one core)
It prints, per variant and seed, trials, failures (and how many of them slipped) and the best theta.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np
import scipy.sparse as sp

from corl.problem import Bounds, Demonstration, Outcome
from corl.realise import project_demonstration
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature

LINKS = np.array([0.35, 0.3, 0.25])
FLAP_X, FLAP_Y, HALF = 0.72, 0.30, 0.04      # the flap's face (x), centre (y) and half length (m)
T_TOUCH, T_RELEASE, DURATION = 1.0, 2.0, 2.4
SLIP = 0.004                                  # m: more slip along the flap while pressing is a failure


def fingertip(q):
    """Fingertip (2,) and its Jacobian (2, 3) for joint angles q (3,)."""
    a = np.cumsum(q)
    x, y = LINKS * np.cos(a), LINKS * np.sin(a)
    J = np.array([[-y[j:].sum() for j in range(3)], [x[j:].sum() for j in range(3)]])
    return np.array([x.sum(), y.sum()]), J


def ik(target, q):
    q = np.array(q, dtype=float)
    for _ in range(200):
        p, J = fingertip(q)
        e = target - p
        if np.linalg.norm(e) < 1e-11:
            break
        q += J.T @ np.linalg.solve(J @ J.T + 1e-8 * np.eye(2), e)
    return q


def _eased(t, knots_t, knots_q):
    """Joint angles (3,) at time t: between knots, a smoothstep from one knot's angles to the next."""
    i = min(int(np.searchsorted(knots_t, t, side="right")) - 1, len(knots_t) - 2)
    s = (t - knots_t[i]) / (knots_t[i + 1] - knots_t[i])
    s = s * s * (3.0 - 2.0 * s)
    return (1.0 - s) * knots_q[i] + s * knots_q[i + 1]


class FlapTask:
    theta_bounds = Bounds(np.array([-0.05]), np.array([0.05]))
    w_bounds = None

    def __init__(self, variant: str = "guide") -> None:
        self.name = f"flap_{variant}"
        self.spline = BSpline(30, 3, duration=DURATION)
        self.q_start = np.array([0.2, 1.3, 1.1])
        self._acc = acceleration_feature(self.spline, 120)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acc])
        self.press_times = ([T_TOUCH, T_RELEASE] if variant in ("guide", "metric")
                            else list(np.linspace(T_TOUCH, T_RELEASE, 21)))
        if variant == "metric":
            self.projection_metric = sp.vstack([self._acc.A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()
        self._problems: dict = {}

    def demonstration(self):
        q_touch = ik(np.array([FLAP_X, FLAP_Y - 0.02]), [0.0, 0.9, 0.9])
        times = np.linspace(0.0, DURATION, 241)
        knots_t = [0.0, 0.6, T_TOUCH, T_RELEASE, DURATION]
        knots_q = [self.q_start, 0.5 * (self.q_start + q_touch) + 0.2, q_touch, q_touch, q_touch - 0.15]
        path = np.array([_eased(t, knots_t, knots_q) for t in times])  # at rest at every knot
        w0 = self.spline.fit(times, path)
        return project_demonstration(self, Demonstration(w0, np.array([-0.02])))[0]

    def method_settings(self):
        from corl.settings import CORLConfig, MethodSettings

        return MethodSettings(corl=CORLConfig(eps_max=0.2, eps_w=1e-4, max_rl_trials=30))

    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta):
        key = float(theta[0])
        if key not in self._problems:
            target = np.array([FLAP_X, FLAP_Y + key])
            self._problems[key] = TrajectoryProblem(self.spline.n, costs=[self._acc], equalities=[
                configuration_feature(self.spline, 0.0, self.q_start),
                TaskSpaceFeature(self.spline, fingertip, self.press_times, target)])
        return self._problems[key]

    def constraint(self, w, theta):
        return self.trajectory_problem(theta).equalities(w)

    def theta_of(self, w):
        return np.array([fingertip(self.spline.positions(w, [T_TOUCH])[0])[0][1] - FLAP_Y])

    def rollout(self, w):
        qs = self.spline.positions(w, np.linspace(T_TOUCH, T_RELEASE, 41))
        tips = np.array([fingertip(q)[0] for q in qs])
        landed = tips[0, 1] - FLAP_Y
        slip = float(np.max(np.linalg.norm(tips - tips[0], axis=1)))
        info = {"landed": float(landed), "slip": slip}
        if abs(tips[0, 0] - FLAP_X) > 0.005 or abs(landed) > HALF or slip > SLIP:
            return Outcome(False, None, info)
        return Outcome(True, math.exp(-((landed - 0.015) / 0.02) ** 2), info)


def make_task(variant: str = "guide") -> FlapTask:
    return FlapTask(variant)


def run(variant: str, seed: int) -> dict:
    from corl.methods import make_method

    learner = make_method("CORL", FlapTask(variant), seed=seed)
    t0 = time.perf_counter()
    best = learner.run()
    told = [o for _, o in learner.history]
    failures = [o for o in told if not o.success]
    return {"variant": variant, "seed": seed, "trials": len(told), "failures": len(failures),
            "slipped": sum(o.info["slip"] > SLIP for o in failures), "theta": float(best.theta[0]),
            "return": float(best.return_), "seconds": time.perf_counter() - t0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--variants", default="guide,metric,interval")
    args = parser.parse_args()
    print(f"{'variant':<9} {'seed':>4} {'trials':>6} {'failures':>8} {'slipped':>7} {'theta*':>8} {'R*':>6} {'s':>5}")
    totals: dict = {}
    for variant in args.variants.split(","):
        for seed in range(args.seeds):
            r = run(variant, seed)
            t = totals.setdefault(variant, [0, 0])
            t[0] += r["trials"]
            t[1] += r["failures"]
            print(f"{variant:<9} {seed:>4} {r['trials']:>6} {r['failures']:>8} {r['slipped']:>7} {r['theta']:>+8.4f} "
                  f"{r['return']:>6.3f} {r['seconds']:>5.1f}", flush=True)
    for variant, (n, f) in totals.items():
        print(f"{variant}: {f} failures in {n} trials")


if __name__ == "__main__":
    main()
