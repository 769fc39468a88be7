"""The PR2 door task of Sec. VIII-B as a :class:`corl.problem.Task`.

Glossary
--------
w       : (n,) B-spline control points of the reference over 8 DoF (7 arm joints + gripper width),
          time-major ``w.reshape(P, 8)``; P = 150 gives n = 1200 (Sec. V-A)
theta   : (2,) (finger position along the handle relative to the demonstration, m;
          finger opening width, m) (Sec. VIII-B)
t_c     : the grasp time; the contact constraints hold at the demonstration's contact waypoints
          (the grasp, pressing the handle, pulling the door), each moved with the handle
h       : Eq. 6 over the contact interval: at each contact time t_k the contact point (between the
          fingertip pads) sits on the bar at ``r0 + theta[0]`` from the pivot, the palm has the
          demonstration's orientation (weighted 0.3 m/rad), and the gripper width is ``theta[1]``
          from the closing on; plus the start configuration held fixed
J       : squared joint accelerations of the reference (Eq. 9), sum over K time steps
R       : ``1 - F / 15 N``, F the mean interaction force at the wrist while the hand works the
          handle (less force is better; order 1)
S       : the door opened past 0.3 rad and the hand kept hold of the handle
c       : (4,) the context (:class:`corl.problem.HasContexts`, :mod:`corl.tasks.door.contexts`),
          measured before a trial: (dz handle height, m; dx door face distance from the robot, m;
          dy door position along the wall, m; yaw of the door about the vertical through the handle
          pivot, rad); c = 0 is the scene of the paper. theta, the contact plan and h are relative
          to the door, so they mean the same in every context; the robot starts from the same rest
          posture in every context
"""

from __future__ import annotations

import copy
import math
import zlib
from dataclasses import replace
from functools import cached_property

import numpy as np

from corl.errors import InputError
from corl.problem import Bounds, Demonstration, Outcome
from corl.tasks.door.contexts import (CONTEXT_BOUNDS, CONTEXT_LABELS, check_context, context_demonstration,
                                      geometry_of_context, rest_start)
from corl.tasks.door.scene import ARM_JOINTS
from corl.tasks.door.demo import (CONTROL_DT, DEMO_DURATION, DEMO_WIDTH, demonstration_waypoints, grasp_rotation,
                                  scripted_demonstration)
from corl.trajectory.bspline import BSpline
from corl.trajectory.features import TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature

__all__ = ["DoorTask", "FORCE_REFERENCE", "return_of_force", "grasp_instant"]

FORCE_REFERENCE = 15.0  # N, about the demonstration's force: R = 1 - F / FORCE_REFERENCE (0 ~ the demonstration)


def return_of_force(force: float) -> float:
    """R of a successful rollout from its mean wrist force (N): ``1 - F / FORCE_REFERENCE``."""
    return 1.0 - float(force) / FORCE_REFERENCE
ROT_WEIGHT = 0.3        # m per rad of palm orientation error in h
EPS_MAX = 0.1           # rad: trust region of one optimization step (Eq. 8), ||w_{i+1} - w_i||


def grasp_instant(t: np.ndarray, q: np.ndarray, tolerance: float = 1e-3) -> float:
    """When the reference (times ``t`` (N,), joints ``q`` (N, 8)) closes the gripper on the handle:
    the first instant its width comes within ``tolerance`` (m) of the width it ends with. The
    interaction window of R and S starts there, so both depend on the motion alone, not on when
    the task's constraints happen to put the grasp."""
    width = q[:, 7]
    return float(t[int(np.argmax(np.abs(width - width[-1]) <= tolerance))])


class DoorTask:
    """Open the door from one scripted demonstration (see the module docstring).

    Parameters
    ----------
    num_control_points : P (150 in the paper).
    num_steps : K, time steps of the acceleration cost (Eq. 9).
    force_noise : std (N) of the error of the force measurement R is computed from; 0 (default)
        keeps the simulator exact. A real wrist sensor is not: with noise, seeds of a benchmark
        differ. The error is a function of ``(seed, w)``, so a trial repeated or replayed from a
        run store reads the same value.
    seed : seeds the measurement error.
    context : (4,) c = (dz, dx, dy, yaw) of the door (:mod:`corl.tasks.door.contexts`); None is 0,
        the paper's scene. A moved door's demonstration is scripted in its scene on first use
        (:func:`corl.tasks.door.contexts.context_demonstration`); h needs none: the contact plan
        relative to the door and the start configuration are those of the unmoved scene.
    """

    name = "door"
    theta_bounds = Bounds(np.array([-0.025, 0.008]), np.array([0.125, 0.028]))
    w_bounds = None
    theta_labels = ("grasp shift along the handle (m)", "finger width (m)")
    joint_names = ARM_JOINTS + ("gripper_width_m",)
    context_bounds = CONTEXT_BOUNDS
    context_labels = CONTEXT_LABELS
    rollout_in_worker = True  # a simulator: `corl run` rolls out in a forked process (corl.tasks.worker)

    def __init__(self, *, num_control_points: int = 150, num_steps: int = 250, force_noise: float = 0.0,
                 seed: int = 0, context=None) -> None:
        from corl.tasks.door.kinematics import Kinematics
        from corl.tasks.door.scene import load_scene

        if not (math.isfinite(force_noise) and force_noise >= 0.0):
            raise InputError(f"force_noise must be a finite standard deviation >= 0 (N), got {force_noise!r}")
        self.force_noise, self.seed = float(force_noise), int(seed)
        self._context = np.zeros(CONTEXT_BOUNDS.dim) if context is None else check_context(context).copy()
        self._moved = bool(np.any(self._context != 0.0))
        self.scene = load_scene(geometry_of_context(self._context)) if self._moved else load_scene()
        self.kin = Kinematics(self.scene)
        if not self._moved:  # the paper's scene: scripted at once, as it always was
            self.demo = scripted_demonstration(self.scene)
        plan = demonstration_waypoints()  # relative to the door: the same in every context
        self.duration = float(DEMO_DURATION)
        self.t_contact = float(next(wp.time for wp in plan if wp.contact and wp.width == DEMO_WIDTH))
        self.spline = BSpline(num_control_points, 8, duration=self.duration)
        self.num_steps = int(num_steps)
        self._acceleration = acceleration_feature(self.spline, self.num_steps)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])
        self._constraints: dict[bytes, TrajectoryProblem] = {}
        # Eq. 6 over the whole interaction: the approach above the bar, the pre-grasp, the closing,
        # pressing and pulling; every waypoint after the start moves with theta
        self.contacts = [wp for wp in plan if wp.time > 0.0]
        self.contact_times = np.array([wp.time for wp in self.contacts])

    # -- contexts (corl.problem.HasContexts) ------------------------------------------------------
    @property
    def context(self) -> np.ndarray:
        """This task's context c (4,) = (dz, dx, dy, yaw) (a copy)."""
        return self._context.copy()

    def with_context(self, c) -> "DoorTask":
        """The same task with the door in context ``c`` (4,): same theta, spline, cost, force noise
        and seed, and the same contact instants (also when this task was re-timed); h, the
        demonstration and the rollout are those of the moved door."""
        c = check_context(c)
        task = type(self)(num_control_points=self.spline.num_control_points, num_steps=self.num_steps,
                          force_noise=self.force_noise, seed=self.seed, context=c)
        if not np.array_equal(task.contact_times, self.contact_times):
            times = self.contact_times.copy()
            task = task.retimed(lambda _: times)
        return task

    # -- the demonstration --------------------------------------------------------------------------
    @cached_property
    def demo(self):
        """The scripted :class:`corl.tasks.door.demo.DoorDemonstration` in this task's scene: a moved
        door's on first use, the first grasp shift whose trial succeeds
        (:func:`corl.tasks.door.contexts.context_demonstration`; DemonstrationFailedError if none)."""
        return context_demonstration(self.scene, self._context,
                                     accept=lambda demo: self.rollout(self.fit_demonstration(demo)).success)

    @cached_property
    def _demo_w(self) -> np.ndarray:
        return self.fit_demonstration(self.demo)

    def fit_demonstration(self, demo) -> np.ndarray:
        """w0 (n,) of a scripted :class:`corl.tasks.door.demo.DoorDemonstration`: its B-spline fit. In a
        moved scene it starts at the rest posture exactly (h holds it there) and, should the fit miss
        a waypoint by more than ``corl.realise.DEMONSTRATION_TOLERANCE``, is projected onto h = 0
        (Eq. 18, :func:`corl.realise.project_demonstration`)."""
        from corl.realise import DEMONSTRATION_TOLERANCE, constraint_violation, project_demonstration

        t = np.arange(int(round(self.duration / CONTROL_DT)) + 1) * CONTROL_DT
        w = self.spline.fit(t, demo.reference(CONTROL_DT))
        if self._moved:
            w[:8] = self._start
            theta = self.theta_of(w)
            if constraint_violation(self, w, theta) > DEMONSTRATION_TOLERANCE:
                w = project_demonstration(self, Demonstration(w, theta))[0].w
        return w

    @cached_property
    def _start(self) -> np.ndarray:
        """The configuration h holds at t = 0 (the first control point, 8,): the same in every context."""
        if not self._moved:
            return self._demo_w[:8]
        return rest_start(self.spline.num_control_points, self.duration)

    def demonstration(self) -> Demonstration:
        """The scripted demonstration as B-spline control points, and its theta = (shift, width): shift
        0 in the paper's scene, where a moved door makes the arm grasp further out (see
        :mod:`corl.tasks.door.contexts`)."""
        w0 = self._demo_w.copy()
        return Demonstration(w0, self.theta_of(w0))

    # -- analytic cost and constraint -----------------------------------------------------------
    def cost_residuals(self, w: np.ndarray):
        """Residuals of Eq. 9 (squared accelerations), sparse Jacobian (K-1) 8 x n."""
        return self._cost.residuals(w)

    def _fk(self, wp, theta=None):
        """Eq. 6 at one contact: contact point (3,), palm orientation error (3,, weighted; the
        small-angle Jacobian, exact at the target), gripper width (1,); theta (unused) moves only the targets."""
        from corl.mujoco import coordinate_feature, orientation_feature, position_feature, stack

        kin = self.kin
        return stack(position_feature(kin, kin.pads),
                     orientation_feature(kin, kin.hand, self._grasp_rotation(wp), weight=ROT_WEIGHT, exact=False),
                     coordinate_feature(8, 7))

    def _grasp_rotation(self, wp) -> np.ndarray:
        return grasp_rotation(wp.phi, wp.alpha, self.scene.geometry.yaw)

    def _targets(self, wp, theta) -> np.ndarray:
        r = wp.r + float(theta[0])
        point = self.scene.handle_point(r, wp.phi, wp.alpha) - wp.backoff * self._grasp_rotation(wp)[:, 0]
        width = float(theta[1]) if wp.width == DEMO_WIDTH else wp.width  # closed from t_c on
        return np.concatenate([point, np.zeros(3), [width]])

    def _constraint_problem(self, theta: np.ndarray) -> TrajectoryProblem:
        key = np.asarray(theta, dtype=float).tobytes()
        problem = self._constraints.get(key)
        if problem is None:
            template = self._constraints.get(b"")  # theta moves only the targets: the features are built once
            if template is None:
                q0 = self._start  # the first control point is the start configuration (clamped)
                eqs = [configuration_feature(self.spline, 0.0, q0)]
                for wp in self.contacts:
                    eqs.append(TaskSpaceFeature(self.spline, self._fk(wp), [wp.time], self._targets(wp, theta)))
                template = TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=eqs)
            problem = template.with_targets([self._targets(wp, theta) for wp in self.contacts])
            if len(self._constraints) > 64:
                self._constraints.clear()
            self._constraints[key] = problem
            self._constraints[b""] = template
        return problem

    def trajectory_problem(self, theta: np.ndarray) -> TrajectoryProblem:
        """Eq. 8 at theta: J of Eq. 9 (banded, linear) under Eq. 6; opts the door in to the SQP solver."""
        return self._constraint_problem(np.asarray(theta, dtype=float).reshape(2))

    def constraint(self, w: np.ndarray, theta: np.ndarray):
        """Eq. 6 over the contact interval and the fixed start: h (q,), sparse dh/dw (q, n)."""
        theta = np.asarray(theta, dtype=float).reshape(2)
        return self._constraint_problem(theta).equalities(w)

    def theta_of(self, w: np.ndarray) -> np.ndarray:
        """Grasp position along the lever (relative to the demonstration) and width at t_c."""
        q = self.spline.positions(w, [self.t_contact])[0]
        p = self.kin.contact_point(q)
        wp = self.contacts[self._grasp_index]
        # at the grasp the door and handle are at rest: handle_point(r) = pivot + R_yaw (-standoff, -r, 0)
        along = self.scene.along_lever(p)
        return np.array([along - wp.r, float(q[7])])

    @cached_property
    def projection_metric(self):
        """Eq. 18 in an acceleration-weighted metric, ``L = [A / 100; 0.1 I]``: the trajectory that
        realises a new theta is the closest one in smoothness, so the whole approach and pull shift
        with the grasp instead of bending only at the constrained instants."""
        import scipy.sparse as sp

        A = self._acceleration.A
        return sp.vstack([A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()

    def method_settings(self):
        """The paper's hyperparameters for the door (Sec. VIII-B)."""
        from corl.settings import DOOR_CLASSIFIER, DOOR_REGRESSION, CORLConfig, MethodSettings

        corl = CORLConfig(eps_max=EPS_MAX, eps_w=1e-5, eps_theta=0.003, max_rounds=6,
                          max_optimization_steps=60, max_rl_trials=60, max_phase_steps=20)
        # The paper gives one length scale per GP; its theta units are not stated. Ours span
        # 150 mm along the handle but only 20 mm in width, so the width dimension gets the
        # paper's length scale times the ratio of the two ranges (ARD, Eq. 16), and PIBU's
        # stopping distance (1e-3, "next point near a sampled one") the same stretch.
        width = self.theta_bounds.width
        ratio = float(width[1] / width[0])
        regression = replace(DOOR_REGRESSION, lengthscale=(DOOR_REGRESSION.lengthscale, DOOR_REGRESSION.lengthscale * ratio))
        classifier = replace(DOOR_CLASSIFIER, lengthscale=(DOOR_CLASSIFIER.lengthscale, DOOR_CLASSIFIER.lengthscale * ratio))
        return MethodSettings(regression=regression, classifier=classifier, corl=corl,
                              direct_budget=150, theta_scale=(1.0, ratio))

    def retimed(self, time_map) -> "DoorTask":
        """The task with its contact instants moved by a phase step (Sec. VI-B): a copy whose Eq. 6
        constraints hold at ``time_map(contact_times)``. The geometry of every contact is unchanged,
        only when it happens; R and S do not depend on it (the rollout finds the grasp from the
        reference itself)."""
        new_times = np.asarray(time_map(self.contact_times), dtype=float)
        if new_times.shape != self.contact_times.shape or np.any(np.diff(new_times) <= 0.0) \
                or new_times[0] <= 0.0 or new_times[-1] > self.duration + 1e-9:
            raise InputError(f"re-timed contact instants {np.round(new_times, 3).tolist()} must stay increasing "
                             f"inside (0, {self.duration}] s")
        task = copy.copy(self)
        task.contacts = [replace(wp, time=float(t)) for wp, t in zip(self.contacts, new_times)]
        task.contact_times = new_times
        task.t_contact = float(new_times[self._grasp_index])
        task._constraints = {}
        return task

    @cached_property
    def _grasp_index(self) -> int:
        return int(np.argmin(np.abs(self.contact_times - self.t_contact)))

    # -- the black box ---------------------------------------------------------------------------
    def reference(self, w: np.ndarray, rate: float = 1.0 / CONTROL_DT):
        """Times (N,) and joint references (N, 8) of ``w`` at ``rate`` Hz (what the robot tracks)."""
        t = np.arange(int(round(self.duration * rate)) + 1) / rate
        return t, self.spline.positions(w, np.minimum(t, self.duration))

    def simulate(self, w: np.ndarray, **kwargs):
        from corl.tasks.door.sim import rollout

        t, q = self.reference(w)
        if not np.all(np.isfinite(q)):
            raise InputError("the reference trajectory contains NaN or inf")
        return rollout(q, duration=self.duration, t_contact=grasp_instant(t, q), scene=self.scene, **kwargs)

    def rollout(self, w: np.ndarray) -> Outcome:
        """Track ``w`` in MuJoCo: R from the wrist force, S from the door angle and the grip."""
        result = self.simulate(w)
        info = {"hinge_final": result.hinge_final, "force_mean": result.force_mean,
                "force_max": result.force_max, "held": result.held, "t_release": result.t_release,
                "handle_max": result.handle_max}
        info = {k: (float(v) if isinstance(v, (float, np.floating)) and math.isfinite(v) else
                    (bool(v) if isinstance(v, (bool, np.bool_)) else None)) for k, v in info.items()}
        if not result.success:
            return Outcome(False, None, info)
        force = self.measured_force(result.force_mean, w)
        if self.force_noise > 0.0:
            info["force_measured"] = force
        return Outcome(True, return_of_force(force), info)

    def measured_force(self, force: float, key: np.ndarray) -> float:
        """What the wrist sensor reports for a true mean force (N): ``force`` plus the seeded error
        (``force_noise``), a function of ``(seed, key)`` so that replaying a policy (``key``: its
        parameters, any array) reads the same value."""
        if self.force_noise == 0.0:
            return float(force)
        digest = zlib.crc32(np.ascontiguousarray(key, dtype=float).tobytes())
        return float(force) + self.force_noise * float(np.random.default_rng([self.seed, digest]).standard_normal())

    # -- for people -----------------------------------------------------------------------------
    def render_comparison(self, w_demo: np.ndarray, w_learned: np.ndarray, path,
                          labels: tuple[str, str] = ("demonstration", "learned")) -> str:
        """An MP4 of the demonstration (left) beside the learned motion (right), captioned with ``labels``."""
        from corl.tasks.door.video import caption, render_rollout, write_side_by_side

        panels = []
        for name, w in zip(labels, (w_demo, w_learned)):
            t, q = self.reference(w)
            frames, result = render_rollout(q, t_contact=grasp_instant(t, q), scene=self.scene)
            r, _ = self.cost_residuals(w)
            panels.append(caption(frames, f"{name}: J = {r @ r:.0f}, force {result.force_mean:.1f} N, "
                                          f"door {np.degrees(result.hinge_final):.0f} deg"))
        return str(write_side_by_side(path, *panels))
