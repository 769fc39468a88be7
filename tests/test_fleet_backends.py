"""``corl run --robots K --backend ray|dask``: the trials rolled out by K Ray actors or Dask workers (corl.fleet)."""

import importlib.util
import json

import pytest
from typer.testing import CliRunner

from corl.cli import app
from corl.errors import InputError
from corl.fleet import run_fleet
from corl.session import StoredRun
from corl.store import RunStore
from corl.tasks.registry import load_task

needs_ray = pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                               reason="needs the extra: pip install 'corl-skills[ray]'")
needs_dask = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                reason="needs the extra: pip install 'corl-skills[dask]'")
runner = CliRunner()


def summary(backend, tmp_path):
    out = tmp_path / backend
    result = runner.invoke(app, ["run", "synthetic", "--robots", "3", "--backend", backend,
                                 "--no-rollout-every-step", "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads((out / "summary.json").read_text()), out / "run.corl"


@pytest.mark.slow
@pytest.mark.parametrize("backend", [pytest.param("ray", marks=needs_ray), pytest.param("dask", marks=needs_dask)])
def test_the_cluster_learns_as_local_processes_do_and_the_store_holds_every_trial(tmp_path, backend):
    local, _ = summary("local", tmp_path)
    remote, store = summary(backend, tmp_path)
    with RunStore(store) as db:
        records = db.trials(1)
    assert [r.proposal.index for r in records] == list(range(len(records)))  # none lost, none twice
    assert all(r.outcome is not None for r in records)  # every trial told
    # the order the workers finish in may differ from the processes': the same learning, not the same trials
    assert remote["trials"] == len(records) and remote["failures"] <= 1.25 * local["failures"] + 1
    assert remote["best_return"] >= 0.98 * local["best_return"]


@needs_ray
def test_a_task_that_cannot_be_pickled_and_has_no_spec_is_refused_in_one_line(tmp_path):
    task = load_task("synthetic", seed=0)
    task.unpicklable = lambda: None  # noqa: E731 (a lambda: pickle refuses it)
    session = StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, robots=2)
    with RunStore(tmp_path / "s.corl") as db, pytest.raises(InputError, match="cannot be pickled") as err:
        session.attach(db)
        run_fleet(session, task, robots=2, backend="ray")
    assert "\n" not in str(err.value)


@needs_dask
@pytest.mark.slow
def test_a_task_without_a_spec_is_sent_to_the_workers_once_and_learns(tmp_path):
    task = load_task("synthetic", seed=0)
    session = StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, robots=2,
                            corl_overrides={"rollout_every_step": False})
    with RunStore(tmp_path / "s.corl") as db:
        session.attach(db)
        told = run_fleet(session, task, robots=2, backend="dask", task_spec=None)
    assert told == len(session.history) > 2 and session.done
    assert session.best is not None and session.best.return_ > 0.9


@needs_dask
@pytest.mark.slow
def test_joins_a_running_dask_cluster_at_its_address(tmp_path):
    import logging

    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=logging.ERROR) as running:
        out = tmp_path / "joined"
        result = runner.invoke(app, ["run", "synthetic", "--robots", "2", "--backend", "dask", "--address",
                                     running.scheduler_address, "--no-rollout-every-step", "--out", str(out)])
        assert result.exit_code == 0, result.output
        assert len(running.scheduler.workers) == 2  # the cluster's own workers, still there: joined, not replaced
    summary = json.loads((out / "summary.json").read_text())
    assert summary["best_return"] > 0.9 and summary["trials"] > 2
