"""Speed of the door simulation, and (with --sweep) the success / force map over theta.

    python benchmarks/door_rollout.py            # compile, IK and rollout wall times; rollout vs the floor
    python benchmarks/door_rollout.py --sweep    # 9 x 7 grid over theta = (shift, width)

The speed table compares one 5 s trial (2500 steps at 500 Hz) four ways, interleaved in one run:

* floor, held: ``mj_step`` 2500 times from the trial's start, set-points and gravity compensation
  written once (MuJoCo's own stepping on a resting arm, no contacts);
* floor, replayed: ``mujoco.rollout`` replaying the trial's recorded inputs (set-points, gravity
  compensation, latch) in C, which reproduces the trial bit for bit: ``mj_step`` on the real
  trajectory, contacts included;
* before: the rollout as it was, per-step Python callbacks and an ``np.isin`` contact check (a copy
  kept below);
* after: :func:`corl.tasks.door.sim.rollout`.

theta = (grasp shift along the lever relative to the demonstration, m; finger opening width, m).
Each grid point re-solves the demonstration's IK with the grasp moved (``shifted_reference``) and
simulates one 5 s trial. A cell prints the mean interaction force (N) of a success, or a failure
code: ``L`` latch never released (handle not pressed far enough), ``H`` hand lost the handle,
``D`` door not past the threshold, ``IK`` no IK solution.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from corl.tasks.door.controller import PDController
from corl.tasks.door.demo import DEMO_GRASP_R, scripted_demonstration, shifted_reference
from corl.tasks.door.scene import load_scene
from corl.tasks.door.sim import (_SAMPLE_EVERY, HOLD_DISTANCE, RolloutResult, _bar_distance, rollout)
from corl.versions import library_versions

# --- before (per-step Python callbacks, np.isin contact check): the rollout as it was -------------


def before_touching(data, geoms_a, geoms_b) -> bool:
    """The old ``corl.mujoco.touching``: four ``np.isin`` over the active contacts."""
    ncon = data.ncon
    if ncon == 0:
        return False
    a, b = np.asarray(geoms_a), np.asarray(geoms_b)
    geoms = data.contact.geom[:ncon]
    return bool(np.any((np.isin(geoms[:, 0], a) & np.isin(geoms[:, 1], b))
                       | (np.isin(geoms[:, 1], a) & np.isin(geoms[:, 0], b))))


def before_track(robot, controller, reference, duration, *, data=None, prepare=None, on_step=None):
    """The old ``corl.mujoco.track``: method calls and fancy indexing every step."""
    import mujoco

    from corl.mujoco import dense_reference

    model = robot.model
    if data is None:
        data = mujoco.MjData(model)
    else:
        mujoco.mj_resetData(model, data)
    q_ref, dq_ref = dense_reference(reference, duration, model.opt.timestep, robot.dim)
    u = controller.setpoints(q_ref, dq_ref)
    controller.initialise(data, q_ref[0])
    if prepare is not None:
        prepare(data)
    controller.apply(data, u[0])
    mujoco.mj_forward(model, data)
    controller.compensate(data)
    mujoco.mj_forward(model, data)
    for k in range(len(q_ref)):
        if k > 0:
            controller.apply(data, u[k])
            controller.compensate(data)
            mujoco.mj_step(model, data)
        if on_step is not None:
            on_step(k, data)
    return data, q_ref


def before_rollout(reference, *, duration=5.0, t_contact=None, scene=None, data=None,
                   controller=None) -> RolloutResult:
    """The old ``corl.tasks.door.sim.rollout`` (without ``on_frame``); ``controller`` replaces the
    door's PDController (to record the inputs of each step)."""
    from corl.mujoco import remove_static_load

    scene = scene or load_scene()
    model = scene.model
    dt = model.opt.timestep
    n = int(round(duration / dt)) + 1
    hinge, handle = np.empty(n), np.empty(n)
    force_raw = np.empty((n, 3))
    rot_ft = np.empty((n, 3, 3))
    grip_t, grip_d, grip_touch = [], [], []
    pads, bar = np.array(scene.tip_geoms), np.array(scene.handle_geoms)
    latch, latch_angle = scene.latch_eq, scene.geometry.latch_angle
    hq, haq, fa = scene.hinge_qpos, scene.handle_qpos, scene.force_adr
    state = {"released": False, "t_release": np.nan, "first_touch": np.nan}

    def latch_on(data):
        data.eq_active[latch] = 1

    def step(k, data):
        if k > 0 and not state["released"] and data.qpos[haq] > latch_angle:
            data.eq_active[latch] = 0
            state["released"], state["t_release"] = True, k * dt
        hinge[k] = data.qpos[hq]
        handle[k] = data.qpos[haq]
        force_raw[k] = data.sensordata[fa:fa + 3]
        rot_ft[k] = data.site_xmat[scene.ft_site].reshape(3, 3)
        if k % _SAMPLE_EVERY == 0:
            touch = before_touching(data, pads, bar)
            if touch and np.isnan(state["first_touch"]):
                state["first_touch"] = k * dt
            grip_t.append(k * dt)
            grip_touch.append(touch)
            grip_d.append(_bar_distance(scene, data, data.site_xpos[scene.pad_sites].mean(axis=0)))

    before_track(scene.robot, controller or PDController(scene), reference, duration, data=data,
                 prepare=latch_on, on_step=step)
    times = np.arange(n) * dt
    force = np.linalg.norm(remove_static_load(force_raw, rot_ft, scene.hand_mass, model.opt.gravity), axis=1)
    t_window = t_contact if t_contact is not None else state["first_touch"]
    grip_t, grip_d, grip_touch = np.array(grip_t), np.array(grip_d), np.array(grip_touch)
    if np.isnan(t_window):
        held, fraction, f_mean, f_max, t_window = False, 0.0, 0.0, 0.0, float("nan")
    else:
        in_window, after = times >= t_window, grip_t >= t_window
        held = bool(np.all(grip_d[after] < HOLD_DISTANCE))
        fraction = float(grip_touch[after].mean()) if after.any() else 0.0
        f_mean, f_max = float(force[in_window].mean()), float(force[in_window].max())
    return RolloutResult(times=times, hinge=hinge, handle=handle, force=force, grip_times=grip_t,
                         grip_distance=grip_d, t_contact=float(t_window), t_release=float(state["t_release"]),
                         held=held, pad_contact_fraction=fraction, force_mean=f_mean, force_max=f_max,
                         info={"first_touch": float(state["first_touch"]), "force_raw": force_raw})


# --- the floors ------------------------------------------------------------------------------------


def _inputs_spec():
    import mujoco

    s = mujoco.mjtState
    return int(s.mjSTATE_CTRL | s.mjSTATE_QFRC_APPLIED | s.mjSTATE_EQ_ACTIVE)


class _Recording(PDController):
    """The door's controller, also keeping what each ``mj_step`` gets: the start state and
    warm-start (at the last compensation before the first step) and each step's inputs."""

    def __init__(self, scene):
        super().__init__(scene)
        self.inputs = []

    def compensate(self, data):
        import mujoco

        super().compensate(data)
        spec = _inputs_spec()
        row = np.empty(mujoco.mj_stateSize(self.robot.model, spec))
        mujoco.mj_getState(self.robot.model, data, row, spec)
        self.inputs.append(row)


def record_trial(scene, ref, t_contact) -> tuple[RolloutResult, np.ndarray, np.ndarray, np.ndarray]:
    """A trial of the old path with its inputs: ``(result, initial_state, warmstart, inputs (K, c))``.

    The first ``compensate`` happens before the initial ``mj_forward``s, the second right before
    ``mj_step`` 1, each later one right before its step; the latch a step sees is the one the hook
    of the previous step left, which is what ``compensate`` reads."""
    import mujoco

    model = scene.model
    starts = {}

    class Start(_Recording):
        def compensate(self, data):
            super().compensate(data)
            if len(self.inputs) == 2:  # the state the first mj_step starts from (after both mj_forward)
                for name, spec in (("state", mujoco.mjtState.mjSTATE_FULLPHYSICS),
                                   ("warm", mujoco.mjtState.mjSTATE_WARMSTART)):
                    starts[name] = np.empty(mujoco.mj_stateSize(model, spec))
                    mujoco.mj_getState(model, data, starts[name], spec)

    ctrl = Start(scene)
    result = before_rollout(ref, t_contact=t_contact, scene=scene, controller=ctrl)
    return result, starts["state"], starts["warm"], np.array(ctrl.inputs[1:])


def replay(scene, state, warm, inputs, data=None):
    """``mujoco.rollout`` of the recorded inputs: qpos (K, nq) of every step."""
    import mujoco
    from mujoco import rollout as mj_rollout

    data = data or mujoco.MjData(scene.model)
    states, _ = mj_rollout.rollout(scene.model, data, state, inputs[None], control_spec=_inputs_spec(),
                                   initial_warmstart=warm[None], skip_checks=False)
    return states[0][:, 1:1 + scene.model.nq]  # the full-physics state: time, qpos, qvel, ...


def held_floor(scene, ref, steps: int, data=None) -> None:
    """``mj_step`` ``steps`` times from the trial's start; set-points and compensation written once."""
    import mujoco

    model = scene.model
    data = data or mujoco.MjData(model)
    mujoco.mj_resetData(model, data)
    ctrl = PDController(scene)
    u = ctrl.setpoints(np.asarray(ref[:1], dtype=float), np.zeros((1, 8)))
    ctrl.initialise(data, ref[0])
    data.eq_active[scene.latch_eq] = 1
    ctrl.apply(data, u[0])
    mujoco.mj_forward(model, data)
    ctrl.compensate(data)
    mujoco.mj_forward(model, data)
    step = mujoco.mj_step
    for _ in range(steps):
        step(model, data)


# --- the tables ------------------------------------------------------------------------------------


def _same(a: RolloutResult, b: RolloutResult) -> bool:
    """Every array and number of two results equal, bit for bit (NaN equal to NaN)."""
    arrays = ("times", "hinge", "handle", "force", "grip_times", "grip_distance")
    scalars = ("t_contact", "t_release", "held", "pad_contact_fraction", "force_mean", "force_max")
    return (all(np.array_equal(getattr(a, f), getattr(b, f)) for f in arrays)
            and all(np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True) for f in scalars)
            and np.array_equal(a.info["force_raw"], b.info["force_raw"])
            and np.array_equal(a.info["first_touch"], b.info["first_touch"], equal_nan=True))


def identity(scene, demo) -> list[tuple[str, bool, bool]]:
    """(name, after == before, replay == before) for the demonstration and shifted references."""
    rows = []
    for theta in (None, [0.03, 0.014], [-0.02, 0.010], [0.08, 0.024], [0.12, 0.028]):
        ref = demo if theta is None else shifted_reference(demo, theta, scene)
        q = ref.reference()
        old, state, warm, inputs = record_trial(scene, q, ref.t_contact)
        new = rollout(q, t_contact=ref.t_contact, scene=scene)
        qpos = replay(scene, state, warm, inputs)
        replay_same = (np.array_equal(qpos[:, scene.hinge_qpos], old.hinge[1:])
                       and np.array_equal(qpos[:, scene.handle_qpos], old.handle[1:]))
        rows.append(("demonstration" if theta is None else f"theta {theta}", _same(old, new), replay_same))
    return rows


def speed(repeats: int = 15) -> None:
    import mujoco

    t0 = time.perf_counter()
    load_scene.cache_clear()
    scene = load_scene()
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    demo = scripted_demonstration(scene)
    t_demo = time.perf_counter() - t0
    t0 = time.perf_counter()
    shifted_reference(demo, [0.03, 0.014], scene)
    t_shift = time.perf_counter() - t0
    ref = demo.reference()
    _, state, warm, inputs = record_trial(scene, ref, demo.t_contact)
    data = mujoco.MjData(scene.model)
    steps = len(inputs)
    runs = {
        "floor, held: mj_step alone, set-points and compensation written once":
            lambda: held_floor(scene, ref, steps, data),
        "floor, replayed: mujoco.rollout of the trial's recorded inputs (exact)":
            lambda: replay(scene, state, warm, inputs, data),
        "before (per-step Python callbacks, np.isin contact check)":
            lambda: before_rollout(ref, t_contact=demo.t_contact, scene=scene, data=data),
        "after (corl.tasks.door.sim.rollout)":
            lambda: rollout(ref, t_contact=demo.t_contact, scene=scene, data=data),
    }
    times = {name: [] for name in runs}
    for _ in range(repeats):  # interleaved, so a busy machine slows each alike
        for name, run in runs.items():
            t0 = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - t0)
    held, replayed = (np.median(ts) for ts in list(times.values())[:2])
    print(f"library versions: {library_versions()}\n")
    print("| what | wall time (s) |\n|---|---|")
    print(f"| scene compile (first, incl. URDF fuse) | {t_compile:.3f} |")
    print(f"| scripted demonstration (IK) | {t_demo:.3f} |")
    print(f"| shifted_reference (IK) | {t_shift:.3f} |")
    print(f"\none 5 s trial ({steps} steps at 500 Hz), the demonstration; {repeats} runs each, interleaved\n")
    print("| path | ms per trial, median | min | / floor (held) | / floor (replayed) |\n|---|---|---|---|---|")
    for name, ts in times.items():
        print(f"| {name} | {1e3 * np.median(ts):.1f} | {1e3 * np.min(ts):.1f} | {np.median(ts) / held:.2f} "
              f"| {np.median(ts) / replayed:.2f} |")
    print("\n| reference | after == before (every array, bit for bit) | replay == before |\n|---|---|---|")
    for name, same, replay_same in identity(scene, demo):
        print(f"| {name} | {same} | {replay_same} |")
    print(f"\ndemonstration: {rollout(ref, t_contact=demo.t_contact, scene=scene).summary()}")


def sweep(n_shift: int = 9, n_width: int = 7) -> None:
    scene = load_scene()
    demo = scripted_demonstration(scene)
    shifts = np.linspace(-0.02, 0.12, n_shift)
    widths = np.linspace(0.010, 0.028, n_width)
    t0 = time.perf_counter()
    rows = []
    for width in widths:
        cells = []
        for shift in shifts:
            try:
                ref = shifted_reference(demo, [shift, width], scene)
            except Exception:
                cells.append("IK")
                continue
            res = rollout(ref.reference(), t_contact=ref.t_contact, scene=scene)
            if res.success:
                cells.append(f"{res.force_mean:.1f}")
            elif np.isnan(res.t_release):
                cells.append("L")
            elif not res.held:
                cells.append("H")
            else:
                cells.append("D")
        rows.append(cells)
    header = " | ".join(f"{DEMO_GRASP_R + s:.3f}" for s in shifts)
    print(f"grasp r from the pivot (m; demo {DEMO_GRASP_R}) across, width (m) down; "
          "success: mean force N\n")
    print(f"| width \\ r | {header} |")
    print("|---" * (n_shift + 1) + "|")
    for width, cells in zip(widths, rows):
        print(f"| {width:.3f} | " + " | ".join(cells) + " |")
    print(f"\n{n_shift * n_width} rollouts in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep", action="store_true", help="sweep theta on a 9 x 7 grid")
    args = parser.parse_args()
    sweep() if args.sweep else speed()
