"""Your own robot: a Franka Panda presses a sprung switch paddle in MuJoCo, built with ``corl.mujoco``.

The Panda of ``example-robot-data`` (URDF and meshes ship in the wheel; nothing is downloaded)
stands in front of a paddle hinged at its far end and held up by a spring. Pressing the paddle's
free end down past 0.2 rad flips the switch. The reference trajectory is a cubic B-spline over the
7 arm joints and the gripper's opening width (Q = 8, P = 40 control points, n = 320).

* theta (1,) : where the closed fingertips press, as the distance from the paddle's hinge (m)
* h(w, theta): from the approach on, the fingertips' midpoint sits on the paddle at ``theta``
               (tilted with it as it turns down to 0.3 rad), the hand is square to the paddle,
               the gripper holds 1 cm; the start configuration is fixed (Eq. 6)
* J(w)       : squared joint accelerations (Eq. 9)
* S          : the switch flipped and the fingertips stayed on the paddle (black box)
* R          : ``1 - F / F_REF``, F the mean contact force the fingertips press with (N): the
               spring needs a torque, so the farther from the hinge, the less force - until the
               fingers slide off the end (unknown to corl)
* c (3,)     : the context (:class:`corl.problem.HasContexts`): where the switch stands, the shift
               (dx, dy, dz) of its hinge from ``HINGE`` in metres, each within +-5 cm. The whole
               scene moves with it (post, paddle, the demonstration's waypoints and start, h's
               targets); theta keeps its meaning. ``c = 0`` is the task above, unchanged.

Run it:  corl run examples.panda_switch:make_task --out results/switch
         corl report --store results/switch/run.corl --out results/switch/report
or:      python examples/panda_switch.py
"""

from __future__ import annotations

import math
from functools import cached_property, lru_cache

import numpy as np

from corl.mujoco import (Camera, ContactPairs, FrameRecorder, Gripper, Kinematics, PDController, Robot, Target,
                         add_joint_equality, add_servos, caption, coordinate_feature, example_robot_dir, fit_demonstration,
                         orientation_feature, parse_mjcf, position_feature, project_demonstration,
                         solve_waypoints, stack, track, urdf_to_mjcf, write_side_by_side)
from corl.problem import Bounds, Demonstration, Outcome, check_theta
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature

ARM = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGERS = ("panda_finger_joint1", "panda_finger_joint2")
KP = (2000.0, 2000.0, 1500.0, 1500.0, 500.0, 500.0, 300.0)  # Nm/rad
KV = (40.0, 40.0, 30.0, 30.0, 8.0, 8.0, 5.0)
EFFORT = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)    # Nm, from the URDF
HINGE = np.array([0.70, 0.0, 0.25])  # the paddle's hinge axis (world y) passes here
LENGTH, THICK = 0.16, 0.02           # m; the paddle reaches from the hinge towards the robot
STIFFNESS, PRELOAD = 1.0, 0.2        # Nm/rad, rad: the spring holds the paddle up against its stop
SWITCH, PRESS = 0.2, 0.3             # rad: the switch flips past SWITCH; the motion presses to PRESS
WIDTH = 0.01                         # m, gripper opening while pressing (the tips nearly closed)
DT, DURATION, T_TOUCH = 0.002, 2.5, 1.2
F_REF = 5.0                          # N, about the demonstration's force: R ~ 0 there
TIP_HALF = 0.009                     # m, half the length of a rubber fingertip pad
R_DEMO = 0.05                        # m from the hinge: a poor spot, near the hinge
# hand pointing down, fingers opening across the paddle (world y)
HAND_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
# the context: the hinge's shift (dx, dy, dz) from HINGE, m
CONTEXT_BOUNDS = Bounds(np.full(3, -0.05), np.full(3, 0.05))
CONTEXT_LABELS = ("switch shift dx: away from the robot (m)", "switch shift dy: to the robot's left (m)",
                  "switch shift dz: up (m)")


def rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def paddle_point(r: float, alpha: float, hinge: np.ndarray = HINGE) -> np.ndarray:
    """The top of the paddle (3,) at distance r from the ``hinge`` (3,), paddle pressed down by alpha (rad)."""
    return hinge + rot_y(-alpha) @ np.array([-r, 0.0, THICK / 2])


def hand_rotation(alpha: float) -> np.ndarray:
    """The hand square to the paddle at alpha: it tilts with it."""
    return rot_y(-alpha) @ HAND_DOWN


@lru_cache(maxsize=1)
def _panda_mjcf() -> str:
    """The Panda's URDF as MJCF text, its idle joints fused (what ``load_spec`` parses): converted
    once per process, an immutable string shared by every context's scene."""
    root = example_robot_dir("panda_description")
    urdf = root / "urdf" / "panda.urdf"
    return urdf_to_mjcf(urdf.read_text(), moving=ARM + FINGERS, base_dir=urdf.parent.resolve(),
                        package_dirs={"package://example-robot-data/robots/panda_description/": root})


def build_robot(hinge: np.ndarray = HINGE) -> Robot:
    """The Panda with position servos, fingertip sites, and the sprung paddle hinged at ``hinge`` (3,)
    in front of it; a fresh model (and so fresh MjData) for every call."""
    import mujoco

    spec = parse_mjcf(_panda_mjcf(), "MJCF made from the URDF")  # = load_spec(panda.urdf), parsed once
    spec.option.timestep = DT
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for body in spec.bodies:  # only the rubber fingertips touch anything, and only the paddle
        for geom in body.geoms:
            geom.contype = geom.conaffinity = 0
        if body.name in ("panda_leftfinger", "panda_rightfinger"):
            tip = max(body.geoms, key=lambda g: g.pos[2])  # the rubber tip is the lowest box
            tip.contype, tip.name, tip.friction = 2, f"{body.name}_tip", [1.0, 0.005, 0.0001]
            side = 1.0 if body.name == "panda_leftfinger" else -1.0
            body.add_site(name=f"{body.name}_tip", pos=[0.0, side * 0.00758, 0.0545], size=[0.003, 0, 0])
    # the hand frame (fused into link 7 with the fixed joints): 0.107 m out, turned -45 deg about z
    spec.body("panda_link7").add_site(name="hand", pos=[0, 0, 0.107], quat=[math.cos(math.pi / 8), 0, 0, -math.sin(math.pi / 8)])
    for name, arm in zip(ARM, (0.1, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05)):
        spec.joint(name).armature = arm
    add_servos(spec, ARM, KP, KV, EFFORT)
    add_servos(spec, FINGERS[:1], (200.0,), (5.0,), (40.0,))
    add_joint_equality(spec, FINGERS[1], FINGERS[0], name="fingers")  # finger 2 = finger 1
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1.5, 1.5, 0.01],
                            rgba=[0.35, 0.4, 0.45, 1], contype=0, conaffinity=0)
    spec.worldbody.add_geom(name="post", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.03, 0.08, hinge[2] / 2],
                            pos=[hinge[0] + 0.03, hinge[1], hinge[2] / 2], rgba=[0.5, 0.5, 0.5, 1], contype=0,
                            conaffinity=0)
    paddle = spec.worldbody.add_body(name="paddle", pos=np.asarray(hinge, dtype=float).tolist())
    paddle.add_joint(name="paddle_hinge", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, -1, 0], range=[0.0, 0.6],
                     limited=True, stiffness=STIFFNESS, springref=-PRELOAD, damping=0.3, armature=0.001)
    paddle.add_geom(name="paddle", type=mujoco.mjtGeom.mjGEOM_BOX, size=[LENGTH / 2, 0.05, THICK / 2],
                    pos=[-LENGTH / 2, 0, 0], mass=0.2, rgba=[0.9, 0.4, 0.1, 1], contype=0, conaffinity=2)
    spec.worldbody.add_light(pos=[0.3, 0, 2.0], dir=[0, 0, -1])
    gripper = Gripper(FINGERS, angle_of=lambda c: 0.5 * np.asarray(c), slope=lambda a: 2.0 + 0.0 * np.asarray(a),
                      lower=0.0, upper=0.08)
    return Robot.from_spec(spec, ARM, gripper)


class PandaSwitchTask:
    """Press the switch paddle where it needs the least force (see the module docstring)."""

    name = "panda_switch"
    theta_bounds = Bounds(np.array([0.03]), np.array([0.19]))
    w_bounds = None
    theta_labels = ("press point: distance from the hinge (m)",)
    joint_names = ARM + ("gripper_width_m",)
    context_bounds = CONTEXT_BOUNDS
    context_labels = CONTEXT_LABELS

    def __init__(self, context=None) -> None:
        c = np.zeros(3) if context is None else check_theta(context, CONTEXT_BOUNDS, task=self.name, what="context")
        self.context = np.array(c, dtype=float)  # own copy: the caller's array may change
        self.hinge = HINGE + self.context        # the paddle's hinge in this scene
        self.robot = build_robot(self.hinge)
        self.kin = Kinematics(self.robot)
        self.tips = self.kin.site("panda_leftfinger_tip", "panda_rightfinger_tip")
        self.hand = self.kin.site("hand")
        self.spline = BSpline(40, 8, duration=DURATION)
        self._acceleration = acceleration_feature(self.spline, 100)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])
        # the waypoints: (time, press angle, height above the paddle); the demonstration's IK knots
        self.waypoints = [(0.8, 0.0, 0.06), (T_TOUCH, 0.0, 0.0), (1.5, 0.1, 0.0), (1.8, 0.2, 0.0),
                          (2.1, PRESS, 0.0), (DURATION, PRESS, 0.0)]
        # Eq. 6 over the whole interaction: every 0.1 s from the approach on, interpolated
        times = np.round(np.arange(0.8, DURATION + 1e-9, 0.1), 10)
        wt = [t for t, _, _ in self.waypoints]
        self.contacts = [(float(t), float(np.interp(t, wt, [a for _, a, _ in self.waypoints])),
                          float(np.interp(t, wt, [u for _, _, u in self.waypoints]))) for t in times]
        self.demo_report = None
        self._problems: dict = {}

    def with_context(self, c) -> "PandaSwitchTask":
        """The same task with the switch's hinge at ``HINGE + c`` (c (3,) in m, inside context_bounds)."""
        return PandaSwitchTask(c)

    def paddle_point(self, r: float, alpha: float) -> np.ndarray:
        """:func:`paddle_point` on this scene's paddle."""
        return paddle_point(r, alpha, self.hinge)

    # -- the demonstration: IK waypoints -> B-spline -> projection onto h = 0 ---------------------
    @cached_property
    def _demo(self) -> tuple[np.ndarray, np.ndarray]:
        start = Target(self.paddle_point(R_DEMO, 0.0) + [-0.12, 0.0, 0.18], HAND_DOWN, gripper=WIDTH)
        targets = [start] + [Target(self.paddle_point(R_DEMO, a) + [0, 0, up], hand_rotation(a), gripper=WIDTH)
                             for _, a, up in self.waypoints]
        seed = np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785, WIDTH])
        knots = solve_waypoints(self.kin, self.tips, targets, seed, start=2, rotation_frame=self.hand)
        times = [0.0] + [t for t, _, _ in self.waypoints]
        w_fit = fit_demonstration(self.spline, times, knots, DT)  # jerky: J has room to improve
        w0, self.demo_report = project_demonstration(self._problem([R_DEMO], q0=knots[0]), w_fit,
                                                     max_error=0.05)
        return w0, knots[0]

    def demonstration(self) -> Demonstration:
        w0, _ = self._demo
        return Demonstration(w0.copy(), self.theta_of(w0))

    def method_settings(self):
        """GP length scales in metres of theta; the trust region in radians of w."""
        from corl.settings import ClassifierConfig, CORLConfig, MethodSettings, RegressionConfig

        return MethodSettings(regression=RegressionConfig(lengthscale=0.04, signal_std=0.5, noise_std=0.01),
                              classifier=ClassifierConfig(lengthscale=0.02, signal_std=10.0, prior_mean=-7.0),
                              corl=CORLConfig(eps_max=0.3, eps_w=1e-4, max_rounds=4, max_optimization_steps=12,
                                              max_rl_trials=25))

    # -- analytic cost and constraint (Eq. 6, 9) ------------------------------------------------
    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta):
        """J (accelerations, Eq. 9) under h(., theta) (Eq. 6) as features: the learner solves it by SQP."""
        return self._problem(theta)

    def constraint(self, w, theta):
        return self._problem(theta).equalities(w)

    def _problem(self, theta, *, q0=None) -> TrajectoryProblem:
        r = float(np.asarray(theta, dtype=float).reshape(-1)[0])
        key = (r, None if q0 is None else np.asarray(q0).tobytes())
        if key not in self._problems:
            eqs = [configuration_feature(self.spline, 0.0, self._demo[1] if q0 is None else q0)]
            for t, alpha, up in self.contacts:
                fk = stack(position_feature(self.kin, self.tips),
                           orientation_feature(self.kin, self.hand, hand_rotation(alpha), weight=0.3),
                           coordinate_feature(8, 7))
                target = np.concatenate([self.paddle_point(r, alpha) + [0, 0, up], np.zeros(3), [WIDTH]])
                eqs.append(TaskSpaceFeature(self.spline, fk, [t], target))
            if len(self._problems) > 64:
                self._problems.clear()
            self._problems[key] = TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=eqs)
        return self._problems[key]

    @cached_property
    def projection_metric(self):
        """Eq. 18 in ``||L (w - w*)||`` with ``L = [A / 100; 0.1 I]`` (A: accelerations): a new theta
        shifts the whole motion smoothly instead of bending it only at the constrained instants."""
        import scipy.sparse as sp

        A = self._acceleration.A
        return sp.vstack([A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()

    def theta_of(self, w):
        q = self.spline.positions(w, [T_TOUCH])[0]
        return np.array([self.hinge[0] - self.kin.position(q, self.tips)[0]])

    # -- the black box ----------------------------------------------------------------------------
    def reference(self, w, rate: float = 1.0 / DT):
        """Times (N,) and joint references (N, 8) of ``w`` at ``rate`` Hz."""
        t = np.arange(int(round(DURATION * rate)) + 1) / rate
        return t, self.spline.positions(w, np.minimum(t, DURATION))

    def run(self, w, on_step=None) -> dict:
        """Track ``w``: the paddle's angle, the press force and where the fingertips were."""
        return self.follow(self.reference(w)[1], on_step)

    def follow(self, q, on_step=None) -> dict:
        """Track joint references ``q`` (N, 8) at the simulation's rate (1 / DT): what :meth:`run` logs."""
        import mujoco

        model = self.robot.model
        hinge = model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "paddle_hinge")]
        tips = [self.robot.id("geom", f"{f}_tip") for f in ("panda_leftfinger", "panda_rightfinger")]
        paddle = [self.robot.id("geom", "paddle")]
        paddle_body = self.robot.id("body", "paddle")
        sites = list(self.tips.ids)
        pairs = ContactPairs(model, paddle, tips)  # tables built once, for the check every 5 steps
        log = {"angle": [], "force": [], "touch": [], "along": [], "gap": []}

        def step(k, data):
            log["angle"].append(float(data.qpos[hinge]))
            if on_step is not None:
                on_step(k, data)
            if k % 5:
                return  # forces and grip at 100 Hz
            log["force"].append(float(np.linalg.norm(pairs.force(data))))
            log["touch"].append(pairs(data))
            local = data.xmat[paddle_body].reshape(3, 3).T @ (data.site_xpos[sites].mean(axis=0) - data.xpos[paddle_body])
            log["along"].append(-local[0])
            log["gap"].append(local[2] - THICK / 2)

        track(self.robot, PDController(self.robot, KP, KV), q, DURATION, on_step=step)
        return {k: np.array(v) for k, v in log.items()}

    @staticmethod
    def press_force(log) -> float:
        """The force R is computed from: the mean contact force from the first touch on (N); NaN untouched."""
        touch = log["touch"]
        return float(log["force"][int(np.argmax(touch)):].mean()) if touch.any() else float("nan")

    def rollout(self, w) -> Outcome:
        return self.judge(self.run(w))

    def execute(self, t, q) -> Outcome:
        """The simulated robot follows a joint trajectory ``q`` (K, 8) at times ``t`` (K,), as a real one would
        (``examples/robot_client.py``); off the simulation's grid it is interpolated linearly onto it."""
        grid = np.arange(int(round(DURATION / DT)) + 1) * DT
        t, q = np.asarray(t, dtype=float), np.asarray(q, dtype=float)
        if t.shape != grid.shape or not np.allclose(t, grid, rtol=0.0, atol=1e-9):
            q = np.column_stack([np.interp(grid, t, q[:, j]) for j in range(q.shape[1])])
        return self.judge(self.follow(q))

    def judge(self, log) -> Outcome:
        """Success and return of a trial from what :meth:`follow` logged."""
        touch = log["touch"]
        info = {"angle_max": float(log["angle"].max())}
        if not touch.any():
            return Outcome(False, None, {**info, "why": "never touched the paddle"})
        after = slice(int(np.argmax(touch)), None)
        # the rubber pads (17.5 mm long) stay whole on the paddle and on its surface
        on_paddle = bool(np.all((log["along"][after] > TIP_HALF) & (log["along"][after] < LENGTH - TIP_HALF)
                                & (np.abs(log["gap"][after]) < 0.02)))
        force = self.press_force(log)
        info.update(force_mean=force, touch_fraction=float(touch[after].mean()), on_paddle=on_paddle)
        if not (info["angle_max"] > SWITCH and on_paddle and info["touch_fraction"] > 0.8):
            return Outcome(False, None, info)
        return Outcome(True, 1.0 - force / F_REF, info)

    def render_comparison(self, w_demo, w_learned, path) -> str:
        """An MP4 of the demonstration (left) beside the learned motion (right), captioned."""
        panels = []
        for name, w in (("demonstration", w_demo), ("learned", w_learned)):
            lookat = tuple(float(v) for v in np.array([0.45, 0.0, 0.35]) + self.context)  # follows the switch
            rec = FrameRecorder(self.robot.model, Camera(lookat=lookat, distance=1.3, azimuth=-90.0, elevation=-10.0))
            try:
                log = self.run(w, on_step=rec)
            finally:
                frames = rec.close()
            r, _ = self.cost_residuals(w)
            panels.append(caption(frames, f"{name}: J = {r @ r:.0f}, press {self.press_force(log):.1f} N"))  # as R
        return str(write_side_by_side(path, *panels))


def make_task(context=None) -> PandaSwitchTask:
    """The switch task; ``context`` (3,): the switch's shift (dx, dy, dz) in m, default none."""
    return PandaSwitchTask(context)


if __name__ == "__main__":
    from corl.methods import make_method

    task = make_task()
    demo = task.demonstration()
    print(task.demo_report)
    print("demonstration:", task.rollout(demo.w))
    learner = make_method("CORL+PIBU", task, seed=0)
    best = learner.run()
    J0 = float(np.sum(task.cost_residuals(demo.w)[0] ** 2))
    fails = sum(not o.success for _, o in learner.history)
    print(f"{len(learner.history)} trials, {fails} failures; theta* = {best.theta[0]:.4f} m, "
          f"R = {best.return_:.3f}, J {J0:.1f} -> {best.J:.1f}")
