"""The door benchmark (Fig. 3): safe-region ground truth, the metrics, DMP+PoWER and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.experiments.door.safe_region import SafeRegion, distance_to_safe


def _region() -> SafeRegion:
    theta1, theta2 = np.array([0.0, 0.1]), np.array([0.01, 0.02, 0.03])
    success = np.array([[False, True, False], [False, False, False]])
    return SafeRegion(theta1, theta2, success, np.ones_like(success), key="test")


def test_distance_to_safe_is_euclidean_in_theta_to_the_nearest_safe_point():
    region = _region()
    assert region.safe_points.tolist() == [[0.0, 0.02]]
    assert distance_to_safe([0.0, 0.02], region) == 0.0
    assert distance_to_safe([0.03, 0.06], region) == pytest.approx(0.05)  # 3-4-5 triangle
    np.testing.assert_allclose(region.spacing, [0.1, 0.01])
    empty = SafeRegion(region.theta1, region.theta2, np.zeros_like(region.success), region.realised, "none")
    assert distance_to_safe([0.0, 0.02], empty) == np.inf


def test_unknown_door_method_is_a_clear_error(tmp_path):
    res = CliRunner().invoke(app, ["bench", "door", "--methods", "CORL+MAGIC", "--out", str(tmp_path)])
    assert res.exit_code == 2 and "unknown method" in res.output


@pytest.mark.slow
def test_tiny_door_sweep_writes_the_fig3_fields_and_two_sided_safe_regions(tmp_path):
    pytest.importorskip("mujoco")
    res = CliRunner().invoke(app, ["bench", "door", "--seeds", "2", "--iterations", "6", "--dmp-iterations", "4",
                                   "--grid", "5x4", "--methods", "CORL+PIBU,DMP+PoWER", "--jobs", "2", "--quiet",
                                   "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    data = json.loads((tmp_path / "door.json").read_text())
    assert set(data["methods"]) == {"CORL+PIBU", "DMP+PoWER"} and "numpy" in data["versions"]
    for name, row in data["methods"].items():
        assert set(row) >= {"seeds", "highest_return_mean", "highest_return_std", "failure_rate_mean",
                            "failure_rate_std", "max_dist_mean", "max_dist_std", "paper"}
        assert row["seeds"] == 2 and 1 <= row["trials_mean"] <= (6 if name == "CORL+PIBU" else 4)
        assert 0.0 <= row["failure_rate_mean"] <= 1.0 and row["max_dist_mean"] >= 0.0
        assert row["highest_return_mean"] >= row["start_return_mean"]  # the start is one of the rollouts
    assert "CORL+PIBU" in res.output and "0.157" in res.output  # the paper's column is printed
    # two anchors (CORL: w* after motion optimization, the same for every seed; DMP: the demonstration)
    cached = sorted(tmp_path.glob("door_safe_region_*.npz"))
    assert len(cached) == 2 and len(data["safe_regions"]) == 2
    for path in cached:
        with np.load(path) as f:
            success = f["success"]
        assert success.shape == (5, 4) and success.any() and not success.all()


@pytest.mark.slow
def test_dmp_power_runs_from_a_successful_fitted_dmp():
    pytest.importorskip("mujoco")
    from corl.experiments.door.dmp import run_dmp_power

    run = run_dmp_power(0, 4)
    assert run.method == "DMP+PoWER" and run.trials == 4 and run.rollouts == 5
    assert np.isfinite(run.start_return)  # the fitted DMP opens the door
    assert run.highest_return >= run.start_return
    assert run.failed_thetas.shape == (run.failures, 2) and np.all(np.isfinite(run.failed_thetas))
