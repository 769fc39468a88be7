"""``corl run --robots K --backend ray``: the trials rolled out by K Ray actors (corl.fleet)."""

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

pytestmark = pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                                reason="needs the extra: pip install 'corl-skills[ray]'")
runner = CliRunner()


def summary(backend, tmp_path):
    out = tmp_path / backend
    result = runner.invoke(app, ["run", "synthetic", "--robots", "3", "--backend", backend,
                                 "--no-rollout-every-step", "--out", str(out), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads((out / "summary.json").read_text()), out / "run.corl"


@pytest.mark.slow
def test_ray_actors_learn_as_local_processes_do_and_the_store_holds_every_trial(tmp_path):
    local, _ = summary("local", tmp_path)
    ray, store = summary("ray", tmp_path)
    with RunStore(store) as db:
        records = db.trials(1)
    assert [r.proposal.index for r in records] == list(range(len(records)))  # none lost, none twice
    assert all(r.outcome is not None for r in records)  # every trial told
    # the order the actors finish in may differ from the processes': the same learning, not the same trials
    assert ray["trials"] == len(records) and ray["failures"] <= 1.25 * local["failures"] + 1
    assert ray["best_return"] >= 0.98 * local["best_return"]


def test_a_task_that_cannot_be_pickled_and_has_no_spec_is_refused_in_one_line(tmp_path):
    task = load_task("synthetic", seed=0)
    task.unpicklable = lambda: None  # noqa: E731 (a lambda: pickle refuses it)
    session = StoredRun.new(task, task_spec="synthetic", method="CORL", seed=0, robots=2)
    with RunStore(tmp_path / "s.corl") as db, pytest.raises(InputError, match="cannot be pickled") as err:
        session.attach(db)
        run_fleet(session, task, robots=2, backend="ray")
    assert "\n" not in str(err.value)
