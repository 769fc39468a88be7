"""ParallelCORL: Algorithm 1 with up to K trials out in its black-box step (corl.parallel)."""

import numpy as np
import pytest

from corl.errors import StateError
from corl.methods import make_method
from corl.parallel import ParallelCORL
from corl.tasks.registry import load_task


@pytest.fixture(scope="module")
def task():
    return load_task("synthetic", seed=0)


def parallel(task, robots):
    corl = make_method("CORL", task, seed=0)
    return ParallelCORL(corl.task, corl.optimizer_factory, corl.config, seed=0, robots=robots)


def fleet(learner, task, order):
    """Keep as many trials out as the learner hands out; tell the ``order``-th oldest first. Returns the
    steps of the trials out together whenever more than one was out."""
    together = []
    while not learner.done:
        while learner.try_ask() is not None:
            pass
        if learner.done:  # Algorithm 1 ended as it was asked for the next trial
            break
        assert learner.pending, "not done, and nothing out to wait for"
        if len(learner.pending) > 1:
            together.append((len(learner.pending), {p.step for p in learner.pending.values()}))
        index = sorted(learner.pending)[min(order, len(learner.pending) - 1)]
        learner.tell(task.rollout(learner.pending[index].w), index)
    return together


def test_one_robot_is_corl_trial_for_trial(task):
    corl = make_method("CORL", task, seed=0)
    corl.run()
    one = parallel(task, 1)
    fleet(one, task, 0)
    assert len(one.history) == len(corl.history)
    for (p, o), (q, r) in zip(one.history, corl.history):
        assert (p.index, p.step) == (q.index, q.step) and np.array_equal(p.w, q.w) and o == r
    assert one.best.return_ == corl.best.return_


@pytest.mark.parametrize("order", [0, 3])
def test_four_robots_share_step_1_and_the_black_box_step_and_lose_nothing(task, order):
    corl = make_method("CORL", task, seed=0)
    corl.run()
    four = parallel(task, 4)
    together = fleet(four, task, order)
    # step 1's chain and step 2 go out together, never mixed; the demonstration and phase steps one at a time
    assert together and all(steps in ({"reinforcement"}, {"optimization"}) for _, steps in together)
    assert {"reinforcement"} in [s for _, s in together] and {"optimization"} in [s for _, s in together]
    assert max(n for n, _ in together) <= 4
    assert sorted(p.index for p, _ in four.history) == list(range(len(four.history)))  # none lost, none twice
    failed = [p.w for p, o in four.history if not o.success]
    for k, w in enumerate(failed):  # a failed motion is never rolled out again
        assert not any(np.linalg.norm(w - v) < four.config.eps_w for v in failed[k + 1:])
    assert sum(not o.success for _, o in four.history) <= 1.25 * sum(not o.success for _, o in corl.history) + 1
    assert four.best.return_ >= 0.98 * corl.best.return_


@pytest.mark.parametrize("order", [0, 3])
def test_step_1_hands_out_the_sequential_chain_and_stops_at_its_first_failure(task, order):
    corl = make_method("CORL", task, seed=0)
    corl.run()
    four = parallel(task, 4)
    fleet(four, task, order)
    chain = lambda history: sorted(((p.index, p.w, o.success) for p, o in history  # noqa: E731
                                    if p.step == "optimization" and p.round == 0), key=lambda x: x[0])
    one, many = chain(corl.history), chain(four.history)
    assert len(one) <= len(many) <= len(one) + 3  # at most K - 1 out beyond the sequential chain's end
    for (_, w, ok), (_, v, ok4) in zip(one, many):  # the same steps in the same order, with the same outcomes
        assert np.array_equal(w, v) and ok == ok4
    assert np.array_equal(four.history[0][0].w, corl.history[0][0].w)


def test_a_tell_names_a_pending_trial(task):
    four = parallel(task, 4)
    first = four.ask()
    assert four.try_ask() is None  # the demonstration goes out alone
    with pytest.raises(StateError, match="not pending"):
        four.tell(task.rollout(first.w), first.index + 1)
    four.tell(task.rollout(first.w), first.index)
    with pytest.raises(StateError, match="not pending"):
        four.tell(task.rollout(first.w), first.index)
