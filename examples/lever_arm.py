"""A context family from the guides alone: a planar 3-link arm throws a sprung lever (no simulator).

The arm of ``examples/planar_button.py`` (links 0.4, 0.3, 0.2 m, base at the origin) reaches a
lever standing on a pivot in front of it, touches its face at ``T_TOUCH``, pushes it forward
(away from the robot) by ``depth`` until ``T_PRESS`` and holds it there until ``DURATION``. A
spring holds the lever back with torque ``k (alpha + PRELOAD)``; the lever clicks past
``CLICK`` rad and hits its stop at ``STOP`` rad. Its reference is a cubic B-spline over the 3
joints (30 control points, n = 90).

* theta (2,) : ``r``, where the fingertip pushes, as the distance from the pivot along the lever
               (m), and ``depth``, how far it throws the lever (rad)
* h(w, theta): the fingertip on the lever's face at ``r``, the lever turned by 0 at the touch and
               by ``depth`` from ``T_PRESS`` on (every 0.1 s of the contact), start fixed (Eq. 6)
* J(w)       : squared joint accelerations (Eq. 9)
* S          : the lever clicked (``alpha_max > CLICK``) without hitting its stop, the fingertip
               stayed on the lever, the push force stayed below ``F_MAX`` and the shoulder's torque
               below ``TAU_MAX`` (the black box does not say so)
* R          : ``1 - F_peak / F_REF - stroke / S_REF - 0.5 exp(-(alpha_max - CLICK) / 0.04)``: little
               force (push far out), a short stroke (push close in) and a clean click; the best
               ``r`` grows with the stiffness (unknown to corl)
* c (3,)     : the context: the pivot's height shift (m), the lever's tilt at rest (rad, + leans
               away from the robot) and the spring's stiffness ``k`` (Nm/rad)

``best_return()`` is the scene's ground truth: the best return over a dense theta grid of the
motion corl runs at each theta (Eq. 8 solved to convergence; ``examples/ground_truth.py``), about
15 s per scene, cached on disk.

Run it:  corl run examples.lever_arm:make_task --context 0,0,1.6 --out results/lever
         corl bench contexts examples.lever_arm:make_task --train 8 --test 8 --seed 0 --out results/lever-bench
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

PIVOT = np.array([0.62, 0.05])       # m, the pivot in the task's own scene
LENGTH, RADIUS = 0.22, 0.01          # m: the lever's length; the fingertip's radius
PRELOAD, CLICK, STOP = 0.3, 0.25, 0.5  # rad
F_MAX, F_REF = 20.0, 25.0            # N: the push force that breaks the lever; R's scale
TAU_MAX = 8.0                        # Nm, the shoulder's torque limit
S_REF = 0.2                          # m, R's scale of the fingertip's stroke while pushing
T_TOUCH, T_PRESS, DURATION = 1.0, 1.6, 2.0
THETA0 = np.array([0.10, 0.30])      # the demonstration: 10 cm up the lever, thrown to 0.3 rad
CONTEXT_BOUNDS = Bounds(np.array([-0.05, -0.15, 0.8]), np.array([0.05, 0.15, 2.4]))
CONTEXT_LABELS = ("pivot height shift (m)", "lever tilt at rest (rad)", "spring stiffness (Nm/rad)")
GRID = (13, 11)                      # best_return's coarse theta grid (r, depth), refined 9 x 9


def lever_frame(beta: float) -> tuple[np.ndarray, np.ndarray]:
    """The lever's direction u (2,) at beta rad from vertical (+: away from the robot), and its
    face's normal n (2,), pointing towards the robot."""
    return np.array([math.sin(beta), math.cos(beta)]), np.array([-math.cos(beta), math.sin(beta)])


class LeverArmTask:
    """Throw the lever with little force and a short stroke (see the module docstring)."""

    name = "lever_arm"
    theta_bounds = Bounds(np.array([0.03, 0.2]), np.array([0.25, 0.55]))
    w_bounds = None
    theta_labels = ("push point: distance from the pivot (m)", "throw depth (rad)")
    context_bounds = CONTEXT_BOUNDS
    context_labels = CONTEXT_LABELS

    def __init__(self, context=None) -> None:
        c = np.array([0.0, 0.0, 1.6]) if context is None else check_theta(context, CONTEXT_BOUNDS, task=self.name,
                                                                           what="context")
        self.context = np.array(c, dtype=float)
        self.pivot = PIVOT + np.array([0.0, self.context[0]])
        self.tilt, self.stiffness = float(self.context[1]), float(self.context[2])
        self.spline = BSpline(30, 3, duration=DURATION)
        self.q_start = np.array([0.3, 1.2, 1.0])
        self._acceleration = acceleration_feature(self.spline, 100)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])
        self.contact_times = np.round(np.arange(T_TOUCH, DURATION + 1e-9, 0.1), 10)

    def with_context(self, c) -> "LeverArmTask":
        return LeverArmTask(c)

    def face_point(self, r: float, alpha: float) -> np.ndarray:
        """Where the fingertip's centre sits touching the lever at r (m), the lever turned by alpha (rad)."""
        u, n = lever_frame(self.tilt + alpha)
        return self.pivot + r * u + RADIUS * n

    @staticmethod
    def angle_at(t: np.ndarray | float, depth: float) -> np.ndarray:
        """The planned lever angle (rad) at times t: 0 at the touch, ``depth`` from T_PRESS on."""
        return depth * np.clip((np.asarray(t, dtype=float) - T_TOUCH) / (T_PRESS - T_TOUCH), 0.0, 1.0)

    # -- the demonstration: IK waypoints, a jerky joint path, projected onto h = 0 -----------------
    @cached_property
    def _demo(self) -> np.ndarray:
        r0, d0 = THETA0
        before = self.face_point(r0, 0.0) + 0.06 * lever_frame(self.tilt)[1]  # 6 cm in front of the face
        q_seed = np.array([0.0, 0.8, 0.8])
        knots = [self.q_start]
        for point in [before] + [self.face_point(r0, a) for a in (0.0, 0.5 * d0, d0, d0)]:
            knots.append(ik(point, knots[-1] if len(knots) > 1 else q_seed))
        times = np.linspace(0.0, DURATION, 201)
        at = [0.0, 0.6, T_TOUCH, 0.5 * (T_TOUCH + T_PRESS), T_PRESS, DURATION]
        path = np.column_stack([np.interp(times, at, [k[j] for k in knots]) for j in range(3)])
        w_fit = self.spline.fit(times, path)
        return project_demonstration(self, Demonstration(w_fit, THETA0.copy()))[0].w  # onto h(w, theta0) = 0

    def demonstration(self) -> Demonstration:
        return Demonstration(self._demo.copy(), self.theta_of(self._demo))

    def method_settings(self):
        """The trust region in radians of w; the GPs are fitted from the data."""
        from corl.settings import CORLConfig, MethodSettings

        return MethodSettings(corl=CORLConfig(eps_max=0.2, eps_w=1e-4, max_rl_trials=60))

    # -- analytic cost and constraint (Eq. 6, 9) ------------------------------------------------
    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta):
        r, depth = (float(v) for v in np.asarray(theta, dtype=float).reshape(-1))
        eqs = [configuration_feature(self.spline, 0.0, self.q_start)]
        for t in self.contact_times:
            eqs.append(TaskSpaceFeature(self.spline, fingertip, [float(t)],
                                        self.face_point(r, float(self.angle_at(t, depth)))))
        return TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=eqs)

    def constraint(self, w, theta):
        return self.trajectory_problem(theta).equalities(w)

    @cached_property
    def projection_metric(self):
        """Eq. 18 in ``||L (w - w*)||``, ``L = [A / 100; 0.1 I]``: a new theta moves the whole press."""
        import scipy.sparse as sp

        return sp.vstack([self._acceleration.A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()

    def contact(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For fingertip centres p (N, 2): the lever angle each pushes it to (rad, 0 when not touching),
        the distance along the lever (m) and the signed gap to the face at rest (m)."""
        d = p - self.pivot
        dist = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        phi = np.arctan2(d[:, 0], d[:, 1])                       # from vertical, + away from the robot
        beta = phi + np.arcsin(np.clip(RADIUS / dist, -1.0, 1.0))  # the lever's angle touching the tip
        alpha = beta - self.tilt
        along = dist * np.cos(phi - beta)
        on = (alpha > 0.0) & (along > 0.0) & (along < LENGTH)
        return np.where(on, alpha, 0.0), along, alpha

    def theta_of(self, w):
        p, _ = fingertip(self.spline.positions(w, [T_PRESS])[0])
        alpha, along, raw = self.contact(p[None, :])
        return np.array([along[0], raw[0]])

    # -- the black box: the lever pushed by the fingertip's path, sampled at 200 Hz ---------------
    def rollout(self, w) -> Outcome:
        t = np.arange(0.0, DURATION + 1e-9, 0.005)
        q = self.spline.positions(w, t)
        tips = [fingertip(qk) for qk in q]
        p = np.array([tp[0] for tp in tips])
        alpha, along, raw = self.contact(p)
        touching = alpha > 0.0
        info = {"alpha_max": float(alpha.max())}
        if not touching.any():
            return Outcome(False, None, {**info, "why": "never touched the lever"})
        first = int(np.argmax(touching))
        after = slice(first, None)
        force = np.where(touching, self.stiffness * (alpha + PRELOAD) / np.maximum(along, 1e-3), 0.0)
        # the lever pushes the fingertip along its face's normal; the shoulder feels J^T f
        tau = np.zeros(len(t))
        for k in np.flatnonzero(touching):
            _, n = lever_frame(self.tilt + alpha[k])
            tau[k] = abs(tips[k][1][:, 0] @ (force[k] * n))
        stroke = float(np.sum(np.linalg.norm(np.diff(p[after], axis=0), axis=1)))
        info.update(force_peak=float(force.max()), tau_peak=float(tau.max()), stroke=stroke,
                    r_mean=float(along[after][touching[after]].mean()),
                    touch_fraction=float(touching[after].mean()))
        stayed = bool(np.all((along[after] > 0.015) & (along[after] < LENGTH - 0.01)))
        why = ("slipped off the lever" if not stayed else "did not click" if info["alpha_max"] <= CLICK
               else "hit the stop" if info["alpha_max"] >= STOP else "pushed too hard" if info["force_peak"] > F_MAX
               else "shoulder torque over its limit" if info["tau_peak"] > TAU_MAX
               else "let go of the lever" if info["touch_fraction"] < 0.9 else "")
        if why:
            return Outcome(False, None, {**info, "why": why})
        margin = info["alpha_max"] - CLICK
        R = 1.0 - info["force_peak"] / F_REF - stroke / S_REF - 0.5 * math.exp(-margin / 0.04)
        return Outcome(True, float(R), info)

    # -- ground truth --------------------------------------------------------------------------------
    def best_return(self) -> float:
        """The best return reachable in this scene: the motion corl runs at each theta of a 13 x 11
        grid, refined by a 9 x 9 grid around its best (examples/ground_truth.py; ~15 s, cached)."""
        return ground_truth.best_return(self, self._demo, GRID)["best_return"]


def make_task(context=None) -> LeverArmTask:
    """The lever task; ``context`` (3,): pivot height shift (m), tilt (rad), stiffness (Nm/rad)."""
    return LeverArmTask(context)


if __name__ == "__main__":
    task = make_task()
    demo = task.demonstration()
    print("demonstration:", demo.theta, task.rollout(demo.w))
