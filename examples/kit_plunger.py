"""A context family on corl's MuJoCo kit: the Panda presses a sprung push-button (a plunger) down.

The Panda of ``examples/panda_switch.py`` (its URDF through ``corl.mujoco``'s public API, its
gains and joint names copied) stands before a push-button: a cap on a vertical slide joint, held up by a
spring. Pressed down past ``CLICK`` it clicks; at ``STOP`` it hits its housing, and a hand that
still pushes presses with the arm's servos against the housing. The reference is a cubic B-spline
over the 7 arm joints and the gripper's width (Q = 8, P = 40, n = 320), as in the switch.

* theta (1,) : how deep the closed fingertips press below the cap's rest height (m)
* h(w, theta): from the approach on, the fingertips' midpoint over the cap's centre, 6 cm above at
               0.8 s, on the cap at ``T_TOUCH``, ``theta`` below from ``T_PRESS`` on; the hand
               pointing down; the gripper at 1 cm; the start fixed (Eq. 6)
* J(w)       : squared joint accelerations (Eq. 9)
* S          : the button clicked, the press force stayed below ``F_MAX`` (not pressed against the
               housing) and the fingertips stayed on the cap (black box)
* R          : ``1 - F / F_REF - 0.5 exp(-(depth - CLICK) / 2 mm)``: F the mean press force, depth
               the deepest the cap went: a sure click for little force (unknown to corl)
* c (3,)     : the context: the button's shift away from the robot and up (m, +-5 cm each) and its
               spring's stiffness (N/m)

``best_return()`` is the scene's ground truth: the best return over a 17-point theta grid refined by
9 points around its best, of the motion corl runs at each theta (Eq. 8 solved to convergence;
``examples/ground_truth.py``): about a minute per scene, cached on disk.

Run it:  corl run examples.kit_plunger:make_task --context 0,0,300 --out results/plunger
"""

from __future__ import annotations

import math
from functools import cached_property, lru_cache

import numpy as np

from corl.mujoco import (ContactPairs, Gripper, Kinematics, PDController, Robot, Target, add_joint_equality,
                         add_servos, coordinate_feature, example_robot_dir, fit_demonstration, load_spec,
                         orientation_feature, position_feature, project_demonstration, solve_waypoints, stack, track,
                         urdf_to_mjcf)
from corl.problem import Bounds, Demonstration, Outcome, check_theta
from corl.trajectory import BSpline, TaskSpaceFeature, TrajectoryProblem, acceleration_feature, configuration_feature
from examples import ground_truth
# the Panda's joints, gains and torque limits, the hand pointing down, as in examples/panda_switch.py
ARM = tuple(f"panda_joint{i}" for i in range(1, 8))
FINGERS = ("panda_finger_joint1", "panda_finger_joint2")
KP = (2000.0, 2000.0, 1500.0, 1500.0, 500.0, 500.0, 300.0)  # Nm/rad
KV = (40.0, 40.0, 30.0, 30.0, 8.0, 8.0, 5.0)
EFFORT = (87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0)  # Nm
HAND_DOWN = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
DT, WIDTH = 0.002, 0.01  # s, the simulation's step; m, the gripper's opening while pressing

BUTTON = np.array([0.60, 0.0, 0.20])  # the cap's top centre at rest, in the task's own scene (m)
CAP = 0.02                            # m, the cap's half width
CLICK, STOP, PRELOAD = 0.008, 0.016, 0.01  # m: the click, the housing, the spring's preload
F_MAX, F_REF = 12.0, 12.0             # N: a press this hard is against the housing; R's scale
DURATION, T_TOUCH, T_PRESS = 2.5, 1.2, 1.8
DEPTH0 = 0.0125                       # m, the demonstration's press depth: just past the click
CONTEXT_BOUNDS = Bounds(np.array([-0.05, -0.05, 150.0]), np.array([0.05, 0.05, 450.0]))
CONTEXT_LABELS = ("button shift away from the robot (m)", "button shift up (m)", "spring stiffness (N/m)")
GRID = (17,)                          # best_return's coarse theta grid, refined by 9 points


@lru_cache(maxsize=1)
def panda_mjcf() -> str:
    """The Panda's URDF as MJCF text (converted once per process; ``load_spec`` reads the text)."""
    root = example_robot_dir("panda_description")
    urdf = root / "urdf" / "panda.urdf"
    return urdf_to_mjcf(urdf.read_text(), moving=ARM + FINGERS, base_dir=urdf.parent.resolve(),
                        package_dirs={"package://example-robot-data/robots/panda_description/": root})


def build_robot(button: np.ndarray, stiffness: float) -> Robot:
    """The Panda with servos and fingertip sites, and the sprung button with its cap's top at ``button``."""
    import mujoco

    spec = load_spec(panda_mjcf(), moving=ARM + FINGERS)
    spec.option.timestep = DT
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for body in spec.bodies:  # only the rubber fingertips touch anything, and only the cap
        for geom in body.geoms:
            geom.contype = geom.conaffinity = 0
        if body.name in ("panda_leftfinger", "panda_rightfinger"):
            tip = max(body.geoms, key=lambda g: g.pos[2])
            tip.contype, tip.name, tip.friction = 2, f"{body.name}_tip", [1.0, 0.005, 0.0001]
            side = 1.0 if body.name == "panda_leftfinger" else -1.0
            body.add_site(name=f"{body.name}_tip", pos=[0.0, side * 0.00758, 0.0545], size=[0.003, 0, 0])
    spec.body("panda_link7").add_site(name="hand", pos=[0, 0, 0.107],
                                      quat=[math.cos(math.pi / 8), 0, 0, -math.sin(math.pi / 8)])
    for name, arm in zip(ARM, (0.1, 0.1, 0.1, 0.1, 0.05, 0.05, 0.05)):
        spec.joint(name).armature = arm
    add_servos(spec, ARM, KP, KV, EFFORT)
    add_servos(spec, FINGERS[:1], (200.0,), (5.0,), (40.0,))
    add_joint_equality(spec, FINGERS[1], FINGERS[0], name="fingers")
    housing_top = float(button[2]) - 0.01 - STOP
    spec.worldbody.add_geom(name="housing", type=mujoco.mjtGeom.mjGEOM_BOX, size=[0.04, 0.04, housing_top / 2],
                            pos=[button[0], button[1], housing_top / 2], rgba=[0.4, 0.4, 0.45, 1], contype=0,
                            conaffinity=0)
    cap = spec.worldbody.add_body(name="cap", pos=np.asarray(button, dtype=float).tolist())
    cap.add_joint(name="plunger", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1], range=[-STOP, 0.0], limited=True,
                  stiffness=float(stiffness), springref=PRELOAD, damping=2.0, armature=0.01)
    cap.add_geom(name="cap", type=mujoco.mjtGeom.mjGEOM_BOX, size=[CAP, CAP, 0.005], pos=[0, 0, -0.005], mass=0.05,
                 rgba=[0.85, 0.15, 0.1, 1], contype=0, conaffinity=2)
    spec.worldbody.add_light(pos=[0.3, 0, 2.0], dir=[0, 0, -1])
    gripper = Gripper(FINGERS, angle_of=lambda c: 0.5 * np.asarray(c), slope=lambda a: 2.0 + 0.0 * np.asarray(a),
                      lower=0.0, upper=0.08)
    return Robot.from_spec(spec, ARM, gripper)


class KitPlungerTask:
    """Click the button surely with little force (see the module docstring)."""

    name = "kit_plunger"
    theta_bounds = Bounds(np.array([0.002]), np.array([0.024]))
    w_bounds = None
    theta_labels = ("press depth below the cap's rest height (m)",)
    joint_names = ARM + ("gripper_width_m",)
    context_bounds = CONTEXT_BOUNDS
    context_labels = CONTEXT_LABELS

    def __init__(self, context=None) -> None:
        c = np.array([0.0, 0.0, 300.0]) if context is None else check_theta(context, CONTEXT_BOUNDS, task=self.name,
                                                                             what="context")
        self.context = np.array(c, dtype=float)
        self.button = BUTTON + np.array([self.context[0], 0.0, self.context[1]])
        self.stiffness = float(self.context[2])
        self.robot = build_robot(self.button, self.stiffness)
        self.kin = Kinematics(self.robot)
        self.tips = self.kin.site("panda_leftfinger_tip", "panda_rightfinger_tip")
        self.hand = self.kin.site("hand")
        self.spline = BSpline(40, 8, duration=DURATION)
        self._acceleration = acceleration_feature(self.spline, 100)
        self._cost = TrajectoryProblem(self.spline.n, costs=[self._acceleration])
        # (time, fraction of the depth pressed, height above the cap) from the approach on, every 0.1 s
        self.contacts = [(float(t), float(np.clip((t - T_TOUCH) / (T_PRESS - T_TOUCH), 0.0, 1.0)),
                          float(np.interp(t, [0.8, T_TOUCH], [0.06, 0.0])))
                         for t in np.round(np.arange(0.8, DURATION + 1e-9, 0.1), 10)]
        self._problems: dict = {}

    def with_context(self, c) -> "KitPlungerTask":
        return KitPlungerTask(c)

    def target(self, depth: float, fraction: float, up: float) -> np.ndarray:
        return self.button + np.array([0.0, 0.0, up - fraction * depth])

    @cached_property
    def _demo(self) -> tuple[np.ndarray, np.ndarray]:
        start = Target(self.button + [-0.12, 0.0, 0.18], HAND_DOWN, gripper=WIDTH)
        waypoints = [(0.8, 0.0, 0.06), (T_TOUCH, 0.0, 0.0), (1.5, 0.5, 0.0), (T_PRESS, 1.0, 0.0), (DURATION, 1.0, 0.0)]
        targets = [start] + [Target(self.target(DEPTH0, f, up), HAND_DOWN, gripper=WIDTH) for _, f, up in waypoints]
        seed = np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785, WIDTH])
        knots = solve_waypoints(self.kin, self.tips, targets, seed, start=2, rotation_frame=self.hand)
        w_fit = fit_demonstration(self.spline, [0.0] + [t for t, _, _ in waypoints], knots, DT)
        w0, _ = project_demonstration(self._problem([DEPTH0], q0=knots[0]), w_fit, max_error=0.05)
        return w0, knots[0]

    def demonstration(self) -> Demonstration:
        w0, _ = self._demo
        return Demonstration(w0.copy(), self.theta_of(w0))

    def method_settings(self):
        """The trust region in radians of w; the GPs are fitted from the data."""
        from corl.settings import CORLConfig, MethodSettings

        return MethodSettings(corl=CORLConfig(eps_max=0.3, eps_w=1e-4, max_rounds=4, max_optimization_steps=12,
                                              max_rl_trials=25))

    def cost_residuals(self, w):
        return self._cost.residuals(w)

    def trajectory_problem(self, theta):
        return self._problem(theta)

    def constraint(self, w, theta):
        return self._problem(theta).equalities(w)

    def _problem(self, theta, *, q0=None) -> TrajectoryProblem:
        depth = float(np.asarray(theta, dtype=float).reshape(-1)[0])
        key = (depth, None if q0 is None else np.asarray(q0).tobytes())
        if key not in self._problems:
            eqs = [configuration_feature(self.spline, 0.0, self._demo[1] if q0 is None else q0)]
            fk = stack(position_feature(self.kin, self.tips),
                       orientation_feature(self.kin, self.hand, HAND_DOWN, weight=0.3), coordinate_feature(8, 7))
            for t, fraction, up in self.contacts:
                target = np.concatenate([self.target(depth, fraction, up), np.zeros(3), [WIDTH]])
                eqs.append(TaskSpaceFeature(self.spline, fk, [t], target))
            if len(self._problems) > 64:
                self._problems.clear()
            self._problems[key] = TrajectoryProblem(self.spline.n, costs=[self._acceleration], equalities=eqs)
        return self._problems[key]

    @cached_property
    def projection_metric(self):
        """Eq. 18 in ``||L (w - w*)||``, ``L = [A / 100; 0.1 I]`` (as the switch's)."""
        import scipy.sparse as sp

        return sp.vstack([self._acceleration.A * 1e-2, 0.1 * sp.identity(self.spline.n)]).tocsr()

    def theta_of(self, w):
        q = self.spline.positions(w, [T_PRESS])[0]
        return np.array([self.button[2] - self.kin.position(q, self.tips)[2]])

    def reference(self, w, rate: float = 1.0 / DT):
        t = np.arange(int(round(DURATION * rate)) + 1) / rate
        return t, self.spline.positions(w, np.minimum(t, DURATION))

    def rollout(self, w) -> Outcome:
        model = self.robot.model
        slide = model.jnt_qposadr[self.robot.id("joint", "plunger")]
        pairs = ContactPairs(model, [self.robot.id("geom", "cap")],
                             [self.robot.id("geom", f"{f}_tip") for f in ("panda_leftfinger", "panda_rightfinger")])
        sites, cap = list(self.tips.ids), self.robot.id("body", "cap")
        log = {"depth": [], "force": [], "touch": [], "off": []}

        def step(k, data):
            if k % 5:
                return
            log["depth"].append(-float(data.qpos[slide]))
            log["force"].append(float(np.linalg.norm(pairs.force(data))))
            log["touch"].append(pairs(data))
            log["off"].append(float(np.max(np.abs(data.site_xpos[sites].mean(axis=0)[:2] - data.xpos[cap][:2]))))

        track(self.robot, PDController(self.robot, KP, KV), self.reference(w)[1], DURATION, on_step=step)
        log = {k: np.array(v) for k, v in log.items()}
        touch = log["touch"]
        info = {"depth_max": float(log["depth"].max())}
        if not touch.any():
            return Outcome(False, None, {**info, "why": "never touched the cap"})
        after = slice(int(np.argmax(touch)), None)
        info.update(force_mean=float(log["force"][after].mean()), force_peak=float(log["force"].max()),
                    touch_fraction=float(touch[after].mean()), off_centre=float(log["off"][after].max()))
        why = ("did not click" if info["depth_max"] < CLICK else "pressed against the housing"
               if info["force_peak"] > F_MAX else "slid off the cap" if info["off_centre"] > CAP - 0.005
               else "let go of the cap" if info["touch_fraction"] < 0.8 else "")
        if why:
            return Outcome(False, None, {**info, "why": why})
        R = 1.0 - info["force_mean"] / F_REF - 0.5 * math.exp(-(info["depth_max"] - CLICK) / 0.002)
        return Outcome(True, float(R), info)

    def best_return(self) -> float:
        """The best return reachable in this scene (examples/ground_truth.py; about a minute, cached)."""
        return ground_truth.best_return(self, self._demo[0], GRID)["best_return"]


def make_task(context=None) -> KitPlungerTask:
    """The push-button task; ``context`` (3,): shift away (m), shift up (m), stiffness (N/m)."""
    return KitPlungerTask(context)


if __name__ == "__main__":
    task = make_task()
    demo = task.demonstration()
    print("demonstration:", demo.theta, task.rollout(demo.w))
