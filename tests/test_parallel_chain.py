"""ParallelCORL's chains (step 1 and the phase steps): K consecutive steps out at once, read in order."""

import numpy as np
import pytest
from test_learner_phase import Nothing, WaypointTask

from corl.learner import CORL, CORLConfig
from corl.parallel import ParallelCORL
from corl.problem import Outcome

CONFIG = CORLConfig(eps_max=0.5, eps_w=1e-6, max_rounds=1, max_optimization_steps=30, max_phase_steps=10)


class FailsAt(WaypointTask):
    """The waypoint task whose rollouts of the motion ``w_fail`` (if any) fail."""

    def __init__(self, w_fail=None):
        super().__init__()
        self.w_fail = w_fail

    def outcome(self, w, step):
        return Outcome(self.w_fail is None or not np.array_equal(w, self.w_fail), 0.0)


def third(step):
    """The third ``step`` motion of CORL's run without failures: the motion to fail."""
    clean = FailsAt()
    corl = learner(clean, 0)
    drive(corl, clean, 0)
    return steps(corl.history, step)[2][1]


def drive(learner, task, order: int):
    """Keep every trial the learner hands out; tell the ``order``-th oldest pending first. Returns the
    sizes of the batches out together."""
    sizes = []
    while not learner.done:
        if isinstance(learner, ParallelCORL):
            while learner.try_ask() is not None:
                pass
            if learner.done:
                break
            sizes.append(len(learner.pending))
            index = sorted(learner.pending)[min(order, len(learner.pending) - 1)]
            p = learner.pending[index]
            learner.tell(task.outcome(p.w, p.step), index)
        else:
            p = learner.ask()
            learner.tell(task.outcome(p.w, p.step))
    return sizes


def learner(task, robots):
    nothing = lambda b, x0, rng: Nothing(b)  # noqa: E731
    return CORL(task, nothing, CONFIG) if robots == 0 else ParallelCORL(task, nothing, CONFIG, robots=robots)


def steps(history, step):
    return sorted(((p.index, p.w, o.success) for p, o in history if p.step == step), key=lambda x: x[0])


@pytest.mark.parametrize("order", [0, 2])
def test_the_chains_go_out_together_and_end_where_corl_ends(order):
    task_one, task_four = FailsAt(), FailsAt()
    one, four = learner(task_one, 0), learner(task_four, 4)
    drive(one, task_one, 0)
    sizes = drive(four, task_four, order)
    assert max(sizes) == 4
    for step in ("optimization", "phase"):
        a, b = steps(one.history, step), steps(four.history, step)
        assert len(a) == len(b) > 1
        assert all(np.array_equal(x[1], y[1]) for x, y in zip(a, b))
    assert np.array_equal(one.best.w, four.best.w) and one.best.J == four.best.J
    np.testing.assert_array_equal(one.task.contact_times, four.task.contact_times)  # the re-timed instants


@pytest.mark.parametrize("step", ["optimization", "phase"])
@pytest.mark.parametrize("order", [0, 2])
def test_a_failure_ends_the_chain_as_in_corl_with_at_most_k_minus_1_more_out(step, order):
    task_one, task_four = FailsAt(third(step)), FailsAt(third(step))
    one, four = learner(task_one, 0), learner(task_four, 4)
    drive(one, task_one, 0)
    drive(four, task_four, order)
    a, b = steps(one.history, step), steps(four.history, step)
    assert [ok for _, _, ok in a][:3] == [True, True, False]
    assert len(a) <= len(b) <= len(a) + 3 and not b[2][2]
    assert all(np.array_equal(x[1], y[1]) for x, y in zip(a[:3], b[:3]))
    # w* is the last success before the chain's first failure, as in CORL; a later success moves nothing
    assert np.array_equal(one.best.w, four.best.w)
    assert one.eps_max == four.eps_max
    np.testing.assert_array_equal(one.task.contact_times, four.task.contact_times)


def test_one_robot_is_corl():
    task_one, task_par = FailsAt(third("phase")), FailsAt(third("phase"))
    one, par = learner(task_one, 0), learner(task_par, 1)
    drive(one, task_one, 0)
    drive(par, task_par, 0)
    assert [(p.index, p.step) for p, _ in one.history] == [(p.index, p.step) for p, _ in par.history]
    assert all(np.array_equal(p.w, q.w) for (p, _), (q, _) in zip(one.history, par.history))
