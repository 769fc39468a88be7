"""A held-out context family: a planar 3-link arm wipes a patch off a tilted wall with a sponge.

Kept aside: the lead engineer runs it once, at the end, to check what was tuned on other families.
No simulator. The arm of ``examples/planar_button.py`` holds a sponge (radius ``RADIUS``) at its
fingertip, touches the wall at ``T_TOUCH``, wipes along it to ``s_end`` by ``T_END`` pressing the
sponge in by ``squeeze``, holds, and lifts off by ``DURATION``. A dirt patch covers the wall from
``PATCH[0]`` to ``PATCH[1]`` (m along it); the wall ends at ``WALL_END``.

* theta (2,) : ``squeeze``, how far the sponge is pressed into the wall (m), and ``s_end``, where the
               wipe ends along the wall (m)
* h(w, theta): the sponge's centre ``RADIUS - squeeze`` off the wall, sliding from 0 to ``s_end``
               over the wipe (every 0.1 s), 3 cm off at the end; the start fixed (Eq. 6)
* J(w)       : squared joint accelerations (Eq. 9)
* S          : the sponge stayed on the wall all through the wipe, its force stayed below ``F_MAX``
               and it did not slide over the wall's end (black box)
* R          : the patch's fraction wiped times ``1 - exp(-F / F_CLEAN)``, less ``F / F_REF``
* c (3,)     : the wall's shift away from the robot (m), its tilt (rad) and the sponge's stiffness
               (N/m)

``best_return()``: the best return over a 13 x 11 theta grid refined by 9 x 9 around its best, of the
motion corl runs at each theta (``examples/ground_truth.py``; about 15 s, cached).
"""

from __future__ import annotations

import math
from functools import cached_property

import numpy as np

from corl.problem import Bounds, Demonstration, Outcome, check_theta
from corl.realise import project_demonstration
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature
from examples import ground_truth
from examples.planar_button import fingertip, ik

WALL = np.array([0.60, -0.02])       # m, where the wipe starts on the wall in the task's own scene
RADIUS = 0.015                       # m, the sponge's radius
PATCH, WALL_END = (0.02, 0.14), 0.20  # m along the wall
F_MAX, F_CLEAN, F_REF = 9.0, 3.0, 40.0  # N
T_TOUCH, T_END, T_LIFT, DURATION = 0.8, 1.6, 1.8, 2.0
THETA0 = np.array([0.004, 0.10])     # the demonstration: 4 mm in, wiping 10 cm
CONTEXT_BOUNDS = Bounds(np.array([-0.05, -0.2, 400.0]), np.array([0.05, 0.2, 1200.0]))
CONTEXT_LABELS = ("wall shift away from the robot (m)", "wall tilt (rad)", "sponge stiffness (N/m)")
GRID = (13, 11)


def wall_frame(gamma: float) -> tuple[np.ndarray, np.ndarray]:
    """The wall's direction t (2,) at gamma rad, and its normal n (2,) towards the robot."""
    return np.array([math.sin(gamma), math.cos(gamma)]), np.array([-math.cos(gamma), math.sin(gamma)])


class HeldoutWipeTask:
    name = "heldout_wipe"
    theta_bounds = Bounds(np.array([-0.004, 0.04]), np.array([0.012, 0.22]))
    w_bounds = None
    theta_labels = ("squeeze (m)", "wipe end along the wall (m)")
    context_bounds = CONTEXT_BOUNDS
    context_labels = CONTEXT_LABELS

    def __init__(self, context=None) -> None:
        c = np.array([0.0, 0.0, 800.0]) if context is None else check_theta(context, CONTEXT_BOUNDS, task=self.name,
                                                                             what="context")
        self.context = np.array(c, dtype=float)
        self.origin = WALL + np.array([self.context[0], 0.0])
        self.along, self.normal = wall_frame(float(self.context[1]))
        self.stiffness = float(self.context[2])
        self.spline = BSpline(30, 3, duration=DURATION)
        self.q_start = np.array([0.3, 1.2, 1.0])
        self._acceleration = acceleration_feature(self.spline, 100)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])
        self.times = np.round(np.arange(T_TOUCH, DURATION + 1e-9, 0.1), 10)

    def with_context(self, c) -> "HeldoutWipeTask":
        return HeldoutWipeTask(c)

    def sponge_at(self, t: float, squeeze: float, s_end: float) -> np.ndarray:
        """Where h puts the sponge's centre (2,) at time t."""
        s = s_end * float(np.clip((t - T_TOUCH) / (T_END - T_TOUCH), 0.0, 1.0))
        off = RADIUS - squeeze + 0.03 * float(np.clip((t - T_LIFT) / (DURATION - T_LIFT), 0.0, 1.0))
        return self.origin + s * self.along + off * self.normal

    @cached_property
    def _demo(self) -> np.ndarray:
        squeeze, s_end = THETA0
        at = [0.0, 0.5, T_TOUCH, 1.2, T_END, T_LIFT, DURATION]
        points = [self.origin + 0.05 * self.normal] + [self.sponge_at(t, squeeze, s_end) for t in at[2:]]
        knots = [self.q_start]
        for point in points:
            knots.append(ik(point, knots[-1] if len(knots) > 1 else np.array([0.0, 0.8, 0.8])))
        times = np.linspace(0.0, DURATION, 201)
        path = np.column_stack([np.interp(times, at, [k[j] for k in knots]) for j in range(3)])
        return project_demonstration(self, Demonstration(self.spline.fit(times, path), THETA0.copy()))[0].w

    def demonstration(self) -> Demonstration:
        return Demonstration(self._demo.copy(), self.theta_of(self._demo))

    def method_settings(self):
        from corl.settings import CORLConfig, MethodSettings

        return MethodSettings(corl=CORLConfig(eps_max=0.2, eps_w=1e-4, max_rl_trials=60))

    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta):
        squeeze, s_end = (float(v) for v in np.asarray(theta, dtype=float).reshape(-1))
        eqs = [configuration_feature(self.spline, 0.0, self.q_start)]
        eqs += [TaskSpaceFeature(self.spline, fingertip, [float(t)], self.sponge_at(float(t), squeeze, s_end))
                for t in self.times]
        return TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=eqs)

    def constraint(self, w, theta):
        return self.trajectory_problem(theta).equalities(w)

    @cached_property
    def projection_metric(self):
        import scipy.sparse as sp

        return sp.vstack([self._acceleration.A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()

    def wall_coordinates(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """For sponge centres p (N, 2): the distance along the wall and the squeeze (m)."""
        d = p - self.origin
        return d @ self.along, RADIUS - d @ self.normal

    def theta_of(self, w):
        p, _ = fingertip(self.spline.positions(w, [T_END])[0])
        s, squeeze = self.wall_coordinates(p[None, :])
        return np.array([squeeze[0], s[0]])

    def rollout(self, w) -> Outcome:
        t = np.arange(0.0, DURATION + 1e-9, 0.005)
        p = np.array([fingertip(q)[0] for q in self.spline.positions(w, t)])
        s, squeeze = self.wall_coordinates(p)
        wipe = (t >= T_TOUCH + 0.05) & (t <= T_LIFT)
        on_wall = (s > -0.03) & (s < WALL_END)
        force = np.where(on_wall & (squeeze > 0.0), self.stiffness * np.maximum(squeeze, 0.0), 0.0)
        info = {"force_peak": float(force.max()), "force_mean": float(force[wipe].mean()),
                "s_max": float(s[squeeze > 0.0].max()) if np.any(squeeze > 0.0) else float("nan")}
        why = ("slid over the wall's end" if np.any(wipe & (squeeze > 0.0) & (s >= WALL_END))
               else "lost the wall" if np.any(force[wipe] <= 0.0)
               else "pressed too hard" if info["force_peak"] > F_MAX else "")
        if why:
            return Outcome(False, None, {**info, "why": why})
        lo, hi = float(s[wipe].min()) - RADIUS, float(s[wipe].max()) + RADIUS
        wiped = max(0.0, min(hi, PATCH[1]) - max(lo, PATCH[0])) / (PATCH[1] - PATCH[0])
        info["wiped"] = wiped
        R = wiped * (1.0 - math.exp(-info["force_mean"] / F_CLEAN)) - info["force_mean"] / F_REF
        return Outcome(True, float(R), info)

    def best_return(self) -> float:
        """The best return reachable in this scene (examples/ground_truth.py; about 15 s, cached)."""
        return ground_truth.best_return(self, self._demo, GRID)["best_return"]


def make_task(context=None) -> HeldoutWipeTask:
    """The wipe; ``context`` (3,): wall shift (m), tilt (rad), sponge stiffness (N/m)."""
    return HeldoutWipeTask(context)
