"""Bring your own task: a planar 3-link arm presses a button, written only against corl's public API.

The arm (link lengths 0.4, 0.3, 0.2 m) starts folded, reaches the button's face at the contact
time t_c = 1.0 s and holds it until T = 2 s. Its reference is a cubic B-spline over the 3 joints
(30 control points, n = 90).

* theta (1,) : where along the button's face the fingertip lands, relative to its centre (m)
* h(w, theta): fingertip at (x_face, y_centre + theta) at t_c (Eq. 6), start configuration fixed
* J(w)       : squared joint accelerations (Eq. 9)
* S(theta)   : the fingertip lands on the button, |theta| < 3 cm (the black box does not say so)
* R(theta)   : how cleanly the switch clicks; best 2 cm off centre, near the edge (unknown to corl)

Run it:  corl run examples.planar_button:make_task --out results/button
or from Python:  python examples/planar_button.py
"""

from __future__ import annotations

import math

import numpy as np

from corl.problem import Bounds, Demonstration, Outcome
from corl.realise import project_demonstration
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature

LINKS = np.array([0.4, 0.3, 0.2])
X_FACE, Y_CENTRE, HALF_WIDTH = 0.75, 0.25, 0.03
T_CONTACT, DURATION = 1.0, 2.0


def fingertip(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Planar forward kinematics: fingertip (2,) and its Jacobian (2, 3)."""
    angles = np.cumsum(q)
    x = LINKS * np.cos(angles)
    y = LINKS * np.sin(angles)
    J = np.zeros((2, 3))
    for j in range(3):
        J[0, j] = -y[j:].sum()
        J[1, j] = x[j:].sum()
    return np.array([x.sum(), y.sum()]), J


def ik(target: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Damped least squares onto a fingertip target (for the scripted demonstration)."""
    q = q.copy()
    for _ in range(200):
        p, J = fingertip(q)
        e = target - p
        if np.linalg.norm(e) < 1e-10:
            break
        q += J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(2), e)
    return q


class PlanarButtonTask:
    name = "planar_button"
    theta_bounds = Bounds(np.array([-0.06]), np.array([0.06]))
    w_bounds = None

    def __init__(self) -> None:
        self.spline = BSpline(30, 3, duration=DURATION)
        self.q_start = np.array([0.3, 1.2, 1.0])
        self._acceleration = acceleration_feature(self.spline, 100)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])

    def demonstration(self) -> Demonstration:
        # scripted: a jerky piecewise-linear reach to 1 cm below the centre, then hold
        q_touch = ik(np.array([X_FACE, Y_CENTRE - 0.01]), np.array([0.0, 0.8, 0.8]))
        times = np.linspace(0.0, DURATION, 201)
        path = np.array([np.interp(times, [0.0, 0.6, T_CONTACT, DURATION],
                                   [self.q_start[j], 0.5 * (self.q_start[j] + q_touch[j]) + 0.3, q_touch[j], q_touch[j]])
                         for j in range(3)]).T
        w0 = self.spline.fit(times, path)  # the fit misses the hold on the face by ~1.5 cm
        return project_demonstration(self, Demonstration(w0, self.theta_of(w0)))[0]  # onto h(w, theta0) = 0

    def method_settings(self):
        """GP length scales in this task's units (theta spans 12 cm), and the trust region."""
        from corl.settings import ClassifierConfig, CORLConfig, MethodSettings, RegressionConfig

        return MethodSettings(regression=RegressionConfig(lengthscale=0.015, signal_std=0.5, noise_std=0.01),
                              classifier=ClassifierConfig(lengthscale=0.01, signal_std=10.0, prior_mean=-7.0),
                              corl=CORLConfig(eps_max=0.2, eps_w=1e-4, max_rl_trials=30))

    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta):
        """J (accelerations, Eq. 9) under h(., theta) (Eq. 6) as features: the learner solves it by SQP."""
        target = np.array([X_FACE, Y_CENTRE + float(theta[0])])
        return TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=[
            configuration_feature(self.spline, 0.0, self.q_start),
            TaskSpaceFeature(self.spline, fingertip, [T_CONTACT, DURATION], target),  # press and hold
        ])

    def constraint(self, w, theta):
        return self.trajectory_problem(theta).equalities(w)

    def theta_of(self, w):
        q = self.spline.positions(w, [T_CONTACT])[0]
        return np.array([fingertip(q)[0][1] - Y_CENTRE])

    def rollout(self, w) -> Outcome:
        q = self.spline.positions(w, [T_CONTACT])[0]
        p, _ = fingertip(q)
        offset = p[1] - Y_CENTRE
        on_face = abs(p[0] - X_FACE) < 0.01 and abs(offset) < HALF_WIDTH
        if not on_face:
            return Outcome(False, None, {"offset": float(offset)})
        return Outcome(True, math.exp(-((offset - 0.02) / 0.02) ** 2), {"offset": float(offset)})


def make_task() -> PlanarButtonTask:
    return PlanarButtonTask()


if __name__ == "__main__":
    from corl.methods import make_method

    task = make_task()
    learner = make_method("CORL+PIBU", task, seed=0)
    best = learner.run()
    J0 = float(np.sum(task.cost_residuals(learner.history[0][0].w)[0] ** 2))
    fails = sum(not o.success for _, o in learner.history)
    print(f"{len(learner.history)} trials, {fails} failures; theta* = {best.theta[0]:+.4f} m, "
          f"R = {best.return_:.3f}, J {J0:.2f} -> {best.J:.2f}")
