"""Algorithm 1 with up to K trials out at once (K robots): :class:`ParallelCORL`.

Where the paper's loop can hand out several trials, it does; where it is sequential, it does not:

* the demonstration (trial 0) and its repeats: one trial out at a time, K = 1 there;
* step 1's trust-region steps (Eq. 8) and the phase steps (Eq. 10), with ``rollout_every_step``,
  each form a chain whose next step is worked out from the last whatever its outcome, a success
  only moving w* along it: up to K consecutive steps go out at once (speculation), their outcomes
  are read in the chain's order as the sequential loop would, and the first failure ends the
  chain as there (step 1 halves eps_max; w* is the last success before it). No new step goes out
  once any step of the chain failed; the steps out beyond a failure are awaited but move nothing
  (the sequential loop would not have run them). Without ``rollout_every_step`` step 1 has one trial;
* step 2, the black-box step over theta, hands out up to K trials: its method is asked with the
  others pending (:attr:`corl.optimizers.base.BlackBoxOptimizer.max_pending`; ``CORL``'s SEIB keeps
  each proposal safe under the told data and apart from the pending ones, with at most one out
  whose success g_S doubts, :data:`corl.optimizers.pending.P_PENDING`), and the outcomes are told
  in whatever order the robots finish. A theta whose projection is infeasible, or whose w failed
  before, is told at once, without a rollout, as in :class:`corl.learner.CORL`. The step ends once
  its method stops (or the budget is spent) and no trial is out; ``theta_step_stop`` does not apply.

Protocol: :meth:`ParallelCORL.try_ask` returns the next trial or None (nothing can go out before a
tell: K are out, a sequential trial is out, or the method has nothing apart from the pending ones);
:meth:`ParallelCORL.tell` takes the outcome and the trial's ``index``. With ``robots = 1`` the trials
are those of :class:`corl.learner.CORL`, one by one.

The generator's messages in step 2: the learner sends ``_ASK`` (hand out a trial) or ``(index,
outcome)`` (a tell); the step yields ``_Out(proposal)``, ``_WAIT`` (nothing now) or ``_IDLE`` (told).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl import checks
from corl.errors import InputError, StateError
from corl.learner import CORL, Best, cost_of
from corl.problem import Outcome, Proposal
from corl.trajectory.solver import solve

__all__ = ["ParallelCORL"]

_ASK, _WAIT, _IDLE = object(), object(), object()


@dataclass(frozen=True)
class _Out:
    proposal: Proposal  # a step-2 trial, handed out at once


class ParallelCORL(CORL):
    """:class:`corl.learner.CORL` whose black-box step keeps up to ``robots`` trials out at once.

    Parameters are CORL's, and ``robots`` (K >= 1). Attributes: :attr:`pending` (index -> Proposal)
    the trials out; ``history`` in the order the outcomes were told.
    """

    def __init__(self, *args, robots: int = 2, **kwargs) -> None:
        self.robots = checks.integer("robots", robots, low=1)
        super().__init__(*args, **kwargs)
        self.pending: dict[int, Proposal] = {}
        self._next: Proposal | None = None  # a sequential trial worked out at a tell, not handed out yet
        self._batch = False  # the generator waits in step 2 for _ASK or a tell
        self._started = False

    # -- ask / tell ----------------------------------------------------------------------------
    def ask(self) -> Proposal:
        """The next trial; StateError when none can go out before a tell (see :meth:`try_ask`)."""
        proposal = self.try_ask()
        if proposal is None:
            raise StateError(f"{len(self.pending)} trial(s) pending and no other can go out before one is told "
                             "(try_ask() returns None then)")
        return proposal

    def try_ask(self) -> Proposal | None:
        """The next trial, handed out now, or None while nothing can go out before a tell (also once
        Algorithm 1 has stopped with trials still out: their tells are awaited)."""
        if self._finished:
            if self.pending:
                return None
            raise StateError("CORL has finished; read .best")
        if len(self.pending) >= self.robots:
            return None
        if self._next is not None:
            proposal, self._next = self._next, None
        elif self._started and not self._batch:
            return None  # a sequential trial is out: its outcome decides the next one
        else:
            try:
                got = self._gen.send(_ASK) if self._started else next(self._gen)
                while got is _IDLE:  # a new black-box step began (its round's step 1 ran no trial): ask it
                    got = self._gen.send(_ASK)
            except StopIteration:
                self._finished = True
                return None
            self._started = True
            if got is _WAIT:
                return None
            self._batch = isinstance(got, _Out)
            proposal = got.proposal if self._batch else got
        self.pending[proposal.index] = proposal
        return proposal

    def tell(self, outcome: Outcome, index: int | None = None) -> None:
        """Record the outcome of pending trial ``index`` (may be left out while one trial is pending)."""
        if not isinstance(outcome, Outcome):
            raise InputError(f"tell() needs a corl.Outcome, got {type(outcome).__name__}")
        if index is None:
            if len(self.pending) != 1:
                raise StateError(f"{len(self.pending)} trials are pending: tell(outcome, index) names which one")
            index = next(iter(self.pending))
        if index not in self.pending:
            raise StateError(f"trial {index} is not pending (pending: {sorted(self.pending)}); each trial is told once")
        proposal = self.pending.pop(index)
        self.history.append((proposal, outcome))
        if not outcome.success:
            self.failed_w.append(np.array(proposal.w, dtype=float))
        try:
            self.J_history.append((proposal.index, cost_of(self.task, proposal.w)))
            got = self._gen.send((index, outcome) if self._batch else outcome)
        except StopIteration:
            self._finished = True
            return
        except Exception:
            self._finished = True
            raise
        self._batch = got is _IDLE
        if not self._batch:
            self._next = got  # the next sequential trial (step 1, phase, or the next round)

    @property
    def done(self) -> bool:
        """Algorithm 1 has stopped and every trial handed out was told."""
        return self._finished and not self.pending

    # -- Algorithm 1 ---------------------------------------------------------------------------
    def _proposal(self, w, theta, step, *, again: bool = False) -> Proposal:
        if not again and self.failed_before(w):
            raise StateError(f"internal error: the learner was about to propose a w that already failed ({step})")
        return Proposal(index=len(self.history) + len(self.pending), w=w, theta=theta, step=step, round=self.rounds)

    def _trajectory_steps(self, problem, w_star, theta_star, r_star):
        """Step 1's chain with up to ``robots`` steps out at once (module docstring); CORL's with one robot."""
        cfg = self.config
        if self.robots == 1 or not cfg.rollout_every_step:
            return (yield from super()._trajectory_steps(problem, w_star, theta_star, r_star))
        task, best = self.task, [w_star, r_star]

        def advance(w_i):  # Eq. 8 from the chain's last step: argmin J s.t. h = 0, ||w - w(i)|| < eps_max
            w_next = solve(problem, w_i, center=w_i, radius=self.eps_max, config=cfg.solver).w
            return None if self._stays(w_next, w_i) else w_next

        def accept(w, r):
            best[:] = w, r
            self._best = Best(w, theta_star, r, cost_of(task, w))

        last, failed = yield from self._chain(w_star, advance, lambda w: w, accept, cfg.max_optimization_steps,
                                              "optimization", theta_star)
        if failed:  # do not walk further into failure; later steps are smaller
            self.eps_max /= 2.0
        return best[0], best[1], last, failed

    def _phase(self, problem, w_star, r_star, w_i, theta_star):
        """The phase steps' chain with up to ``robots`` steps out at once; CORL's with one robot."""
        cfg = self.config
        if self.robots == 1 or not cfg.rollout_every_step:
            return (yield from super()._phase(problem, w_star, r_star, w_i, theta_star))
        candidate, best = self._phase_step(theta_star), [w_star, r_star]

        def advance(state):  # one phase step from the chain's last: (task, problem, w, J), kept if it lowers J
            task, problem, w, J = state
            found = candidate(task, problem, w)
            return None if found is None or found[3] >= J or self._stays(found[2], w) else found

        def accept(state, r):
            best[:] = state[2], r
            self._best = Best(state[2], theta_star, r, state[3])
            self.task = state[0]  # the re-timed contacts hold from here on

        last, _ = yield from self._chain((self.task, problem, w_i, cost_of(self.task, w_i)), advance, lambda s: s[2],
                                         accept, cfg.max_phase_steps, "phase", theta_star)
        return best[0], best[1], last[2]

    def _chain(self, start, advance, w_of, accept, max_steps: int, step: str, theta_star):
        """Up to ``robots`` consecutive steps of a chain out at once; their outcomes read in the chain's
        order, ``accept(state, return)`` at each success until the first failure. ``advance(state)`` is
        the next state, or None where the chain ends. Returns (the last state handed out, whether one failed)."""
        state, steps, ended, failed, doomed = start, 0, False, False, False
        chain: list[int] = []  # the trials out, in the chain's order
        of: dict[int, object] = {}
        told: dict[int, Outcome] = {}
        message = yield _IDLE
        while True:
            if message is _ASK:
                proposal = None
                if not (ended or doomed) and steps < max_steps:
                    following = advance(state)
                    steps += 1
                    if following is None:
                        ended = True
                    else:
                        state = following
                        proposal = self._proposal(w_of(state), theta_star, step)
                        chain.append(proposal.index)
                        of[proposal.index] = state
                if proposal is None and not chain:
                    break
                message = yield _WAIT if proposal is None else _Out(proposal)
                continue
            index, outcome = message
            told[index] = outcome
            doomed = doomed or not outcome.success  # no new step goes out once one failed
            while chain and chain[0] in told:  # in the chain's order, as the sequential loop reads them
                k = chain.pop(0)
                first = told.pop(k)
                if not failed and first.success:
                    accept(of[k], float(first.return_))
                failed = failed or not first.success
            if not chain and (failed or ended or steps >= max_steps):
                break
            message = yield _IDLE
        return state, failed

    def _reinforcement(self, w_star, theta_star, r_star, data):
        """Step 2 with up to ``robots`` trials out (module docstring); the same end as CORL's."""
        task, cfg = self.task, self.config
        rng = np.random.default_rng([self.seed, self.rounds])
        optimizer = self.optimizer_factory(task.theta_bounds, theta_star.copy(), rng)
        if hasattr(optimizer, "recheck_failures"):  # a failed w is never run again here
            optimizer.recheck_failures = False
        self.optimizers.append(optimizer)
        for theta, outcome in data:  # Alg. 1: Initialize D
            optimizer.tell(theta, outcome)
        optimizer.max_pending = self.robots
        candidates: list[tuple[np.ndarray, np.ndarray, float]] = []
        out: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # trial index -> (theta, w) of the trials out

        def over() -> bool:  # the step has nothing more to hand out
            return self.rl_trials >= cfg.max_rl_trials or optimizer.done

        message = yield _IDLE
        while True:
            if message is _ASK:
                proposal = None
                while proposal is None and self.rl_trials < cfg.max_rl_trials and optimizer.ready:
                    theta = optimizer.ask()  # theta(d+1): safe given the data and the trials out
                    self.rl_trials += 1
                    w, outcome = self._realised(w_star, theta_star, theta)  # Eq. 18
                    if outcome is None:
                        proposal = self._proposal(w, theta, "reinforcement")
                        out[proposal.index] = (theta, w)
                        continue
                    optimizer.tell(theta, outcome)
                    data.append((theta, outcome))
                if proposal is None and not out:  # the step is over (its method stopped, or the budget)
                    break
                message = yield _WAIT if proposal is None else _Out(proposal)
            else:
                index, outcome = message
                theta, w = out.pop(index)
                if outcome.success:
                    candidates.append((w, theta, float(outcome.return_)))
                optimizer.tell(theta, outcome)  # add datapoint to D
                data.append((theta, outcome))
                if not out and over():
                    break
                message = yield _IDLE
        return self._step_end(optimizer, candidates, w_star, theta_star, r_star, data)
