"""corl sweep: the ground truth of a simulated task over theta (issue 12, item 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError
from corl.experiments.sweep import TaskSpec, parse_grid, sweep_task, write_sweep
from corl.problem import Bounds, Demonstration, Outcome
from corl.realise import realise

CENTRE, RADIUS = np.array([0.2, -0.1]), 0.45


class Disk:
    """theta = w (2,) through a nonlinear h (w cubed); S: theta in a disk; R peaks at (0.3, 0.1)."""

    name = "disk"
    theta_bounds = Bounds(np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    w_bounds = None

    def demonstration(self):
        return Demonstration(np.zeros(2), np.zeros(2))

    def cost_residuals(self, w):
        return np.asarray(w, dtype=float), np.eye(2)

    def constraint(self, w, theta):
        w = np.asarray(w, dtype=float)
        return w + w ** 3 - theta, np.diag(1 + 3 * w ** 2)

    def theta_of(self, w):
        return w + w ** 3

    def rollout(self, w):
        theta = self.theta_of(w)
        if np.linalg.norm(theta - CENTRE) >= RADIUS:
            return Outcome(False)
        return Outcome(True, float(-np.sum((theta - np.array([0.3, 0.1])) ** 2)))


def make_disk():
    return Disk()


def test_the_sweep_of_a_toy_task_recovers_its_known_success_region(tmp_path):
    result = sweep_task(make_disk, (21, 17))
    points = result.points
    truth = np.linalg.norm(points - CENTRE, axis=1) < RADIUS
    assert result.realised.all()
    np.testing.assert_array_equal(result.success.ravel(), truth)
    R = result.returns.ravel()
    np.testing.assert_allclose(R[truth], -np.sum((points[truth] - [0.3, 0.1]) ** 2, axis=1), atol=1e-8)
    assert np.isnan(R[~truth]).all()
    files = write_sweep(result, tmp_path, labels=("a", "b"))
    doc = json.loads(open(files["json"]).read())
    assert doc["successes"] == int(truth.sum()) and doc["grid"] == [21, 17]
    k = int(np.argmax(np.where(truth, R, -np.inf)))
    assert doc["best"]["theta"] == pytest.approx(points[k].tolist())
    rows = open(files["csv"]).read().splitlines()
    assert rows[0] == "theta1,theta2,realised,success,return" and len(rows) == 1 + 21 * 17
    assert open(files["png"], "rb").read(4) == b"\x89PNG"


def test_the_synthetic_sweep_matches_the_paper_definition():
    result = sweep_task(TaskSpec("synthetic"), (61,))
    theta = result.axes[0]
    truth = (theta > -1.5) & (theta < 2.5)  # S(theta) of Sec. VIII-A
    np.testing.assert_array_equal(result.success, truth)
    # a realisation is feasible to max|h| <= 1e-5 (FEASIBILITY_FACTOR x tol_constraint), and |dR/dtheta| < 4
    R = -0.5 * theta[truth] ** 2 + np.cos(3 * theta[truth])
    np.testing.assert_allclose(result.returns[truth], R, atol=4 * 1e-5)


def test_parallel_sweep_equals_the_serial_one():
    serial = sweep_task(TaskSpec("synthetic", 3), (13,))
    parallel = sweep_task(TaskSpec("synthetic", 3), (13,), jobs=2)
    np.testing.assert_array_equal(serial.success, parallel.success)
    np.testing.assert_array_equal(serial.returns, parallel.returns)


def test_realise_is_what_the_sweep_uses():
    task = Disk()
    r = realise(task, np.zeros(2), np.zeros(2), np.array([0.5, -0.7]))
    assert r.feasible and r.pieces == 0
    np.testing.assert_allclose(task.theta_of(r.w), [0.5, -0.7], atol=1e-6)
    with pytest.raises(InputError, match="outside the bounds"):
        realise(task, np.zeros(2), np.zeros(2), np.array([1.5, 0.0]))


def test_realise_continues_from_theta_star_when_the_direct_projection_fails():
    class Fold(Disk):
        """h = sin(w) - theta: from w* = 3 (near the fold at pi/2 ... 3pi/2) a direct projection to theta
        near the far side must stay on the branch; continuation follows it."""

        theta_bounds = Bounds(np.array([-1.0, -1.0]), np.array([1.0, 1.0]))

        def constraint(self, w, theta):
            w = np.asarray(w, dtype=float)
            return np.sin(w) - theta, np.diag(np.cos(w))

    task = Fold()
    w_star = np.array([0.3, 0.3])
    r = realise(task, w_star, np.sin(w_star), np.array([-0.9, 0.95]))
    assert r.feasible
    np.testing.assert_allclose(np.sin(r.w), [-0.9, 0.95], atol=1e-5)


def test_parse_grid():
    assert parse_grid("25,15", 2) == (25, 15)
    assert parse_grid("25x15", 2) == (25, 15)
    assert parse_grid("9", 3) == (9, 9, 9)
    for bad, dim in (("25,3", 3), ("a,b", 2), ("1,5", 2)):
        with pytest.raises(InputError, match="--grid"):
            parse_grid(bad, dim)


def test_corl_sweep_command(tmp_path):
    res = CliRunner().invoke(app, ["sweep", "synthetic", "--grid", "21", "--out", str(tmp_path), "--json", "-q"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["points"] == 21 and 0 < doc["successes"] < 21
    assert set(doc["files"]) == {"csv", "json", "png"}
    bad = CliRunner().invoke(app, ["sweep", "synthetic", "--grid", "3,3", "--out", str(tmp_path)])
    assert bad.exit_code == 2 and bad.output.startswith("error: --grid '3,3' gives 2 sizes, but theta has 1")
