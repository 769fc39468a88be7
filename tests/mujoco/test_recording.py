"""A task from a recording: the loader, the replay's contacts, the refusals, h's Jacobian (issue 35)."""

from __future__ import annotations

import numpy as np
import pytest

from corl.errors import InputError

mujoco = pytest.importorskip("mujoco")

from corl.mujoco import Recording, Robot, find_contacts, load_recording, parse_mjcf, save_recording  # noqa: E402

# A point finger (three slides, a 1 cm sphere) above a sprung button (a box on a vertical slide) and a
# crate on the other side; no gravity. The button's top is at z = 0.07, the crate's at z = 0.09.
SCENE = """
<mujoco>
  <option timestep="0.002" gravity="0 0 0"/>
  <worldbody>
    <geom name="table" type="box" size="0.6 0.6 0.01" pos="0 0 -0.3"/>
    <body name="finger" pos="0 0 0.3">
      <joint name="x" type="slide" axis="1 0 0" range="-1 1"/>
      <joint name="y" type="slide" axis="0 1 0" range="-1 1"/>
      <joint name="z" type="slide" axis="0 0 1" range="-1 1"/>
      <geom name="tip" type="sphere" size="0.01" mass="0.1"/>
    </body>
    <body name="button" pos="0.3 0 0.05">
      <joint name="press" type="slide" axis="0 0 1" range="-0.03 0.01" stiffness="200" damping="5"/>
      <geom name="button" type="box" size="0.05 0.04 0.02" mass="0.2"/>
    </body>
    <body name="crate" pos="-0.3 0 0.05">
      <joint name="crate_slide" type="slide" axis="1 0 0" damping="5"/>
      <geom name="crate" type="box" size="0.04 0.04 0.04" mass="0.5"/>
    </body>
  </worldbody>
</mujoco>
"""
SIZE = 0.10  # m, the button's largest extent: tolerances scale with it


def robot() -> Robot:
    return Robot.from_spec(parse_mjcf(SCENE), ("x", "y", "z"))


def press(waypoints, rate: float = 100.0) -> Recording:
    """A recording through ``waypoints`` [(t, x, y, z of the sphere's centre)], linear between them."""
    w = np.array(waypoints, dtype=float)
    t = np.arange(int(round(w[-1, 0] * rate)) + 1) / rate
    q = np.column_stack([np.interp(t, w[:, 0], w[:, j]) for j in (1, 2, 3)]) - [0.0, 0.0, 0.3]
    return Recording(t, q, ("x", "y", "z"))


# the sphere's bottom 4 mm into the button's top at (0.32, 0.01): button frame (0.02, 0.01, 0.02)
TOUCH = press([(0.0, 0.32, 0.01, 0.2), (0.8, 0.32, 0.01, 0.076), (1.5, 0.32, 0.01, 0.076), (2.0, 0.32, 0.01, 0.2)])


# -- the loader ------------------------------------------------------------------------------------
def test_npz_and_csv_round_trip(tmp_path):
    for name in ("r.npz", "r.csv"):
        back = load_recording(save_recording(tmp_path / name, TOUCH.t, TOUCH.q, TOUCH.joints))
        assert back.joints == ("x", "y", "z")
        np.testing.assert_allclose(back.q, TOUCH.q, atol=1e-8)
        np.testing.assert_allclose(back.t, TOUCH.t, atol=1e-9)


@pytest.mark.parametrize("name, content, says", [
    ("a.txt", "t,x\n0,1\n", "a .npz or a .csv"),
    ("a.csv", "", "empty"),
    ("a.csv", "time,x\n0,1\n1,2\n", "header must be t,"),
    ("a.csv", "t,x\n0,1\n1,oops\n", "row 3 holds something that is not a number"),
    ("a.csv", "t,x,y\n0,1,2\n1,2\n", "row 3 has 2 fields"),
    ("a.csv", "t,x\n0,1\n0,2\n", "times must increase"),
    ("a.csv", "t,x\n0,1\n1,nan\n", "NaN or inf in sample 1"),
    ("a.csv", "t,x\n0,1\n", "at least two"),
    ("a.npz", b"not a zip", "not a readable .npz"),
])
def test_bad_files_are_refused_in_one_line(tmp_path, name, content, says):
    path = tmp_path / name
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    with pytest.raises(InputError, match=says) as err:
        load_recording(path)
    assert "\n" not in str(err.value)


def test_npz_without_q_and_a_missing_file(tmp_path):
    np.savez(tmp_path / "a.npz", t=np.arange(3.0))
    with pytest.raises(InputError, match="no array 'q'"):
        load_recording(tmp_path / "a.npz")
    with pytest.raises(InputError, match="no recording at"):
        load_recording(tmp_path / "missing.npz")


def test_columns_must_be_the_robots_joints():
    with pytest.raises(InputError, match="not the robot's joints"):
        find_contacts(robot(), Recording(TOUCH.t, TOUCH.q, ("y", "x", "z")), "button")
    with pytest.raises(InputError, match="2 joint columns"):
        find_contacts(robot(), Recording(TOUCH.t, TOUCH.q[:, :2]), "button")


# -- contacts --------------------------------------------------------------------------------------
def test_contact_interval_and_point_on_a_known_scene():
    contacts = find_contacts(robot(), TOUCH, "button")
    assert contacts.object_joints == ("press",)
    (iv,) = contacts.intervals
    # the sphere's bottom reaches the top (z 0.07) at 0.8 * (0.2 - 0.08) / (0.2 - 0.076) = 0.774 s, leaves at 1.52 s
    assert iv.start == pytest.approx(0.774, abs=0.02) and iv.end == pytest.approx(1.52, abs=0.02)
    assert iv.geoms == ("tip",) and iv.bodies == ("finger",)
    np.testing.assert_allclose(iv.point[:2], [0.02, 0.01], atol=0.01 * SIZE)   # on the top, where it pressed
    assert abs(iv.point[2] - 0.02) < 0.05 * SIZE
    np.testing.assert_allclose(iv.normal, [0, 0, 1], atol=1e-6)               # out of the top
    np.testing.assert_allclose(iv.offsets[0], [0, 0, -0.01], atol=0.05 * SIZE)  # the sphere's bottom
    assert iv.slide < 0.01 * SIZE
    assert contacts.size == pytest.approx(SIZE)
    # the button was pushed down: the replay moved it, and the point is read in its moving frame
    press_q = contacts.qpos[:, robot().model.jnt_qposadr[3]]
    assert press_q.min() < -0.002


def _lift(height: float) -> Recording:
    """TOUCH with the sphere lifted off the button for 0.3 s in the middle, its bottom ``height``
    above the button's resting top (z 0.07)."""
    up = 0.07 + height + 0.01
    return press([(0.0, 0.32, 0.01, 0.2), (0.8, 0.32, 0.01, 0.076), (0.9, 0.32, 0.01, 0.076), (0.95, 0.32, 0.01, up),
                  (1.25, 0.32, 0.01, up), (1.3, 0.32, 0.01, 0.076), (1.5, 0.32, 0.01, 0.076), (2.0, 0.32, 0.01, 0.2)])


def test_a_break_that_stays_near_the_object_does_not_split_the_contact():
    # 1 mm off the top for 0.3 s (longer than gap): still the one push, as a bouncing object is
    (iv,) = find_contacts(robot(), _lift(0.001), "button").intervals
    assert iv.start == pytest.approx(0.774, abs=0.02) and iv.end == pytest.approx(1.52, abs=0.02)
    # the same break with near=0, or lifted 2 cm: two contacts
    for contacts in (find_contacts(robot(), _lift(0.001), "button", near=0.0),
                     find_contacts(robot(), _lift(0.02), "button")):
        first, second = contacts.intervals
        assert first.end < 0.97 and second.start > 1.23
    with pytest.raises(InputError, match="near=-0.1"):
        find_contacts(robot(), TOUCH, "button", near=-0.1)


def test_the_object_is_found_when_not_named_and_any_rate_works():
    fast = find_contacts(robot(), TOUCH, None)
    slow = find_contacts(robot(), press([(0.0, 0.32, 0.01, 0.2), (0.8, 0.32, 0.01, 0.076), (1.5, 0.32, 0.01, 0.076),
                                         (2.0, 0.32, 0.01, 0.2)], rate=7.0), None)
    assert fast.object == slow.object == "button"
    np.testing.assert_allclose(fast.intervals[0].point, slow.intervals[0].point, atol=0.01 * SIZE)


# -- refusals --------------------------------------------------------------------------------------
def test_a_recording_that_never_touches_the_object_is_refused():
    above = press([(0.0, 0.32, 0.01, 0.2), (2.0, 0.32, 0.01, 0.15)])
    with pytest.raises(InputError, match=r"never touches 'button' \(2.00 s replayed at 500 Hz\); it touches nothing"):
        find_contacts(robot(), above, "button")
    crate = press([(0.0, -0.3, 0.0, 0.2), (0.8, -0.3, 0.0, 0.096), (1.5, -0.3, 0.0, 0.2)])
    with pytest.raises(InputError, match="never touches 'button'.*it touches 'crate'"):
        find_contacts(robot(), crate, "button")


def test_a_recording_that_touches_two_objects_is_refused():
    both = press([(0.0, 0.32, 0.01, 0.2), (0.5, 0.32, 0.01, 0.076), (0.8, 0.32, 0.01, 0.2), (1.6, -0.3, 0.0, 0.2),
                  (2.0, -0.3, 0.0, 0.096), (2.4, -0.3, 0.0, 0.2)])
    with pytest.raises(InputError, match="touches several candidate objects: 'button' .*'crate'") as err:
        find_contacts(robot(), both, "button")
    assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="name the object"):
        find_contacts(robot(), both, None)


def test_a_sliding_contact_is_refused_naming_its_interval():
    slide = press([(0.0, 0.30, 0.0, 0.2), (0.6, 0.30, 0.0, 0.076), (1.4, 0.34, 0.0, 0.076), (2.0, 0.34, 0.0, 0.2)])
    with pytest.raises(InputError, match=r"slid 4\d.\d mm along its surface during 0\.\d\d-1\.\d\d s.*open case") as err:
        find_contacts(robot(), slide, "button")
    assert "\n" not in str(err.value)
    (iv,) = find_contacts(robot(), slide, "button", slide_tolerance=0.05).intervals  # a looser tolerance lets it be
    assert iv.slide == pytest.approx(0.04, abs=0.05 * SIZE)


def test_h_of_the_known_scene_holds_the_demonstration_and_theta_moves_it():
    from corl.mujoco import RecordedTask

    task = RecordedTask(robot(), find_contacts(robot(), TOUCH, "button"), lambda log: 0.0, lambda log: True)
    assert task.theta_labels == ("contact point along x of 'button' (m)", "contact point along y of 'button' (m)")
    np.testing.assert_allclose(task.theta_bounds.lower, [-0.05, -0.04], atol=1e-9)  # the button's top, from its box
    np.testing.assert_allclose(task.theta_bounds.upper, [0.05, 0.04], atol=1e-9)
    demo = task.demonstration()
    np.testing.assert_allclose(demo.theta, [0.02, 0.01], atol=0.01 * SIZE)
    assert np.max(np.abs(task.constraint(demo.w, demo.theta)[0])) < 1e-6
    problem = task.trajectory_problem(demo.theta + [0.01, -0.02])
    from corl.trajectory.solver import project

    w = project(problem.equalities, demo.w).w
    np.testing.assert_allclose(task.theta_of(w), demo.theta + [0.01, -0.02], atol=1e-6)



def test_pinned_instants_keep_the_path_within_the_tolerance():
    """Closed form: targets on a straight line at constant speed need only the first, the contact's
    first and the last instant; a kink adds its instant; every instant left out lies within the
    tolerance of the line between the kept ones around it; a tolerance below the bend keeps all."""
    from corl.mujoco.recorded import pinned_instants

    t = np.linspace(0.0, 1.0, 21)
    eye = np.eye(3)[:, :1]
    line = [(float(s), np.array([s, 0.0, 0.0]), eye, None, 0.0) for s in t]
    assert pinned_instants(line, np.zeros(1), 0.5, 1e-3) == [0, 10, 20]
    bent = [(float(s), np.array([s, 0.1 * max(0.0, s - 0.3), 0.0]), eye, None, 0.0) for s in t]
    kept = pinned_instants(bent, np.zeros(1), 0.0, 1e-3)
    assert 6 in kept and kept[0] == 0 and kept[-1] == 20  # the kink at t = 0.3
    path = np.array([x[1] for x in bent])
    for a, b in zip(kept[:-1], kept[1:]):
        s = (t[a:b + 1] - t[a]) / (t[b] - t[a])
        assert np.max(np.linalg.norm(path[a:b + 1] - (path[a] + s[:, None] * (path[b] - path[a])), axis=1)) <= 1e-3
    curve = [(float(s), np.array([np.cos(s), np.sin(s), 0.0]), eye, None, 0.0) for s in t]
    assert pinned_instants(curve, np.zeros(1), 0.0, 1e-6) == list(range(21))
    grip = [(float(s), np.zeros(3), eye, None, 0.02 * (s > 0.52)) for s in t]  # the gripper closes
    assert {10, 11} <= set(pinned_instants(grip, np.zeros(1), 0.0, 1e-3))


def test_a_tolerance_pins_fewer_instants_and_h_still_holds_the_demonstration():
    from corl.mujoco import RecordedTask

    contacts = find_contacts(robot(), TOUCH, "button")
    every = RecordedTask(robot(), contacts, lambda log: 0.0, lambda log: True)
    fewer = RecordedTask(robot(), contacts, lambda log: 0.0, lambda log: True, tolerance=0.002)
    assert 2 <= len(fewer.times[0]) < len(every.times[0])
    assert set(np.round(fewer.times[0], 9)) <= set(np.round(every.times[0], 9))
    demo = fewer.demonstration()
    np.testing.assert_allclose(demo.theta, every.demonstration().theta, atol=0.01 * SIZE)
    assert np.max(np.abs(fewer.constraint(demo.w, demo.theta)[0])) < 1e-6
    with pytest.raises(InputError, match="tolerance"):
        RecordedTask(robot(), contacts, lambda log: 0.0, lambda log: True, tolerance=0.0)


def test_retimed_moves_the_instants_and_keeps_where_the_contact_is():
    """Phase steps (Sec. VI-B) move h's instants: the identity map gives the same h, a shift moves
    every instant and keeps each target, theta_of reads at the moved first contact instant, the
    original task is unchanged, and a map that reverses time is refused."""
    from corl.mujoco import RecordedTask

    task = RecordedTask(robot(), find_contacts(robot(), TOUCH, "button"), lambda log: 0.0, lambda log: True)
    demo = task.demonstration()
    same = task.retimed(lambda t: np.asarray(t))
    np.testing.assert_array_equal(same.constraint(demo.w, demo.theta)[0], task.constraint(demo.w, demo.theta)[0])
    before = [t.copy() for t in task.times]
    later = task.retimed(lambda t: np.asarray(t) + 0.05)
    np.testing.assert_allclose(later.times[0], before[0] + 0.05, atol=1e-12)
    np.testing.assert_array_equal(task.times[0], before[0])
    for old, new in zip(task._targets[0], later._targets[0]):
        assert new[0] == pytest.approx(old[0] + 0.05) and np.array_equal(new[1], old[1]) and np.array_equal(new[2], old[2])
    first = later._first[0]
    shifted = later.spline.positions(demo.w, [later.times[0][first]])[0]
    point = later.kin.position(shifted, later.frames[0])
    t0, base, M, _, _ = later._targets[0][first]
    np.testing.assert_allclose(later.theta_of(demo.w), M.T @ (point - base), atol=1e-12)
    with pytest.raises(InputError, match="re-timed instants"):
        task.retimed(lambda t: -np.asarray(t))

# -- a grasp: the object follows the pinched point -------------------------------------------------
# A carriage (slides x, z) with two fingers (slides along y) pinches a bar hinged about y at
# (0.3, 0, 0.1), 8 cm from the hinge, and lifts it along its arc to 0.3 rad; no gravity.
PINCH_SCENE = """
<mujoco>
  <option timestep="0.002" gravity="0 0 0"/>
  <worldbody>
    <body name="carriage" pos="0 0 0.1">
      <joint name="x" type="slide" axis="1 0 0" range="-1 1"/>
      <joint name="z" type="slide" axis="0 0 1" range="-1 1"/>
      <geom type="sphere" size="0.005" contype="0" conaffinity="0" mass="0.1"/>
      <body name="left" pos="0 0.03 0">
        <joint name="left" type="slide" axis="0 1 0" range="-0.03 0.03"/>
        <geom name="left" type="box" size="0.005 0.005 0.005" mass="0.05"/>
      </body>
      <body name="right" pos="0 -0.03 0">
        <joint name="right" type="slide" axis="0 1 0" range="-0.03 0.03"/>
        <geom name="right" type="box" size="0.005 0.005 0.005" mass="0.05"/>
      </body>
    </body>
    <body name="bar" pos="0.3 0 0.1">
      <joint name="bar_hinge" type="hinge" axis="0 1 0" range="-0.6 0.6" damping="0.01"/>
      <geom name="bar" type="box" size="0.08 0.01 0.01" pos="-0.08 0 0" mass="0.2"/>
    </body>
  </worldbody>
</mujoco>
"""
R_PINCH, LIFT = 0.08, 0.3


def pinch() -> Recording:
    """Open, close on the bar (0.3-0.6 s), lift it along its arc to LIFT (0.8-1.8 s), hold, at 100 Hz."""
    t = np.arange(201) / 100.0
    angle = LIFT * np.clip((t - 0.8) / 1.0, 0.0, 1.0)
    close = 0.0155 * np.clip((t - 0.3) / 0.3, 0.0, 1.0)  # the faces 0.5 mm into the bar's sides
    q = np.column_stack([0.3 - R_PINCH * np.cos(angle), R_PINCH * np.sin(angle), -close, close])
    return Recording(t, q, ("x", "z", "left", "right"))


def test_a_grasped_object_follows_the_pinch_and_the_point_holds():
    robot = Robot.from_spec(parse_mjcf(PINCH_SCENE), ("x", "z", "left", "right"))
    contacts = find_contacts(robot, pinch(), "bar", grasp=True)
    (iv,) = contacts.intervals
    assert iv.start == pytest.approx(0.58, abs=0.03) and iv.end == pytest.approx(2.0, abs=0.01)
    assert set(iv.bodies) == {"left", "right"}
    np.testing.assert_allclose(iv.point, [-R_PINCH, 0.0, 0.0], atol=0.01 * R_PINCH)  # on the bar's axis, 8 cm out
    np.testing.assert_allclose(np.abs(iv.normal), [0.0, 1.0, 0.0], atol=1e-3)        # the squeeze axis
    assert iv.slide < 0.01 * R_PINCH
    angle = contacts.qpos[:, robot.model.jnt_qposadr[robot.id("joint", "bar_hinge")]]
    assert angle[-1] == pytest.approx(LIFT, abs=0.01) and abs(angle[contacts.step(0.7)]) < 0.01


def test_grasp_needs_the_objects_name():
    robot = Robot.from_spec(parse_mjcf(PINCH_SCENE), ("x", "z", "left", "right"))
    with pytest.raises(InputError, match="grasp=True needs the grasped object's name"):
        find_contacts(robot, pinch(), None, grasp=True)


def test_the_grip_as_theta_moves_the_held_gripper_value():
    from corl.mujoco import Gripper, RecordedTask

    gripper = Gripper(("left", "right"), ratios=(-1.0, 1.0))  # c: how far each finger closed (m)
    robot = Robot.from_spec(parse_mjcf(PINCH_SCENE), ("x", "z"), gripper)
    rec = pinch()
    contacts = find_contacts(robot, Recording(rec.t, rec.q[:, :3] * [1, 1, -1]), "bar", grasp=True)
    task = RecordedTask(robot, contacts, lambda log: 0.0, lambda log: True, directions=("-x",),
                        grip_bounds=(0.012, 0.02))
    assert task.theta_labels[-1].startswith("gripper while it holds")
    np.testing.assert_allclose(task.theta0, [R_PINCH, 0.0155], atol=0.01 * R_PINCH)
    assert (task.theta_bounds.lower[-1], task.theta_bounds.upper[-1]) == (0.012, 0.02)
    demo = task.demonstration()
    np.testing.assert_allclose(demo.theta, task.theta0, atol=1e-6)
    from corl.trajectory.solver import project

    theta = demo.theta + [-0.02, 0.003]
    w = project(task.trajectory_problem(theta).equalities, demo.w).w
    np.testing.assert_allclose(task.theta_of(w), theta, atol=1e-6)
    with pytest.raises(InputError, match="grip_bounds needs a robot with a gripper"):
        RecordedTask(Robot.from_spec(parse_mjcf(PINCH_SCENE), ("x", "z", "left", "right")),
                     find_contacts(Robot.from_spec(parse_mjcf(PINCH_SCENE), ("x", "z", "left", "right")), pinch(),
                                   "bar", grasp=True), lambda log: 0.0, lambda log: True, grip_bounds=(0.0, 0.02))
