"""CORL, Algorithm 1, as an ask/tell learner.

Glossary
--------
w*, theta* : best policy so far (Alg. 1 "Initialize (w*, theta*) = (w0, theta0)"), (n,) and (m,)
R*         : return of the best policy's latest successful rollout
D          : data of the black-box step, pairs (theta, Outcome)
eps_max    : trust-region radius of one optimization step (Eq. 8)
eps_w      : step 1 stops when ``||w(i+1) - w(i)|| < eps_w``
eps_theta  : step 2 stops when ``||theta(d+1) - theta(d)|| < eps_theta`` (if ``theta_step_stop``)

The algorithm is written once, as a generator that yields :class:`Proposal` objects and receives
:class:`Outcome` objects; :meth:`CORL.ask` and :meth:`CORL.tell` drive it. A robot's loop is

    learner = CORL(task, pibu_factory())
    while not learner.done:
        proposal = learner.ask()
        outcome = execute_on_robot(proposal.w)
        learner.tell(outcome)

Decisions beyond the paper (see README):
* The demonstration is rolled out once, as trial 0: D needs ``R(theta0)``, and a failing
  demonstration is reported at once (:class:`DemonstrationFailedError`).
* A step-1 iterate that moved less than ``eps_w`` is not rolled out (it is the same policy); with
  ``CORLConfig.min_J_decrease`` > 0, neither is one that lowers J by less than that fraction.
* A failed rollout in step 1 ends that step; ``w*`` stays at the last success, and the trust
  region of every later step-1 step is halved (``eps_max / 2`` per failure). Eq. 8's trust region
  exists because a step is "not guaranteed to lead to task success" (Sec. VI-A); a failure is the
  evidence that steps of this size leave the success region here (success depends on the path, not
  only on theta, against Sec. IV's assumption), so later rounds try a smaller step from the same
  ``w*`` instead of the step that failed. A failure still ends the loop when the round made no
  other progress ("until no change in (w*, theta*)").
* A failed w is never proposed again: every w within ``eps_w`` of a failed trial's w is refused
  (step 1 and phase steps stop before it; in step 2 the theta is told the recorded failure
  without a rollout, ``info["known_failure"] = True``).
* ``h(w0, theta0) ~ 0`` is checked when the learner is built, before anything is rolled out
  (:func:`corl.realise.check_demonstration`, ``CORLConfig.demo_tolerance``).
* With ``reuse_data`` (default), D keeps the step-2 data of earlier rounds: R and S depend on
  theta only (Sec. IV), so the data stays valid and a converged black-box step stops at once.
* Eq. 18 may have no minimiser (the infimum can sit where h is singular); any feasible result
  realises theta and is executed, and an infeasible one is retried by continuation from theta*
  (:func:`corl.realise.realise`). A theta whose projection stays infeasible is told to the black-box method as a failure
  without a rollout (``info["unrealisable"] = True``) and counted in ``unrealisable``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Generator, Iterator

import numpy as np

from corl import checks
from corl.errors import DemonstrationFailedError, InputError, StateError
from corl.config import CORLConfig
from corl.loop import drive
from corl.optimizers.base import BlackBoxOptimizer, StopReason
from corl.problem import Bounds, Outcome, Proposal, Task
from corl.realise import check_demonstration, feasible, motion_problem, realise
from corl.speculation import _Speculation
from corl.trajectory.solver import solve

__all__ = ["CORLConfig", "CORL", "Best", "OptimizerFactory", "best_observed", "cost_of"]

OptimizerFactory = Callable[[Bounds, np.ndarray, np.random.Generator], BlackBoxOptimizer]


@dataclass(frozen=True)
class Best:
    """The best policy so far: ``w`` (n,), ``theta`` (m,), its return and analytic cost J.

    ``return_`` is the reading of w*'s trial. With ``CORL`` (whose return model fits the noise)
    theta* is the learner's best: the sampled theta with the highest posterior mean of R among those
    the model does not doubt, so not the luckiest reading; ``return_std`` is one reading's noise (g_R's
    fitted noise std). With the paper's methods theta* has the highest reading (Alg. 1 as published)
    and ``return_std`` is NaN. ``reading`` repeats the trial's reading."""

    w: np.ndarray
    theta: np.ndarray
    return_: float
    J: float
    return_std: float = float("nan")
    reading: float | None = None


def best_observed(history) -> tuple[Proposal, Outcome] | None:
    """The ``(proposal, outcome)`` of ``history`` with the highest successful reading (the first of
    equal ones), or None: the *best observed* trial, never called "best return"."""
    ok = [(p, o) for p, o in history if o.success and o.return_ is not None]
    return max(ok, key=lambda t: t[1].return_, default=None)


def cost_of(task: Task, w: np.ndarray) -> float:
    """Analytic cost ``J(w) = r(w) @ r(w)`` (Eq. 7)."""
    r, _ = task.cost_residuals(w)
    return float(np.dot(r, r))


class CORL:
    """Algorithm 1: alternate trust-region motion optimization and safe black-box RL over theta.

    Parameters
    ----------
    task : a :class:`corl.problem.Task`.
    optimizer_factory : ``(bounds, theta_start, rng) -> BlackBoxOptimizer`` builds the black-box
        method of step 2 (PIBU, UCB, SAL, CMA-ES, PoWER) afresh in every round.
    config : :class:`CORLConfig`.
    seed : seeds the black-box methods; same seed and outcomes give the same proposals.

    Notes
    -----
    The budget: ``config.max_rl_trials`` is the number of black-box trials (step 2's thetas)
    over the whole run, all rounds together. The start theta* of a round is not one of them (its
    return comes from step 1); a theta whose Eq. 18 projection stays infeasible is (the method is
    told a failure). The optimizer the factory builds is not trusted to count: the learner stops
    step 2 at the budget itself (:attr:`rl_trials`). Step 1's rollouts are bounded by
    ``max_optimization_steps`` per round and ``max_rounds``.

    :attr:`stop_reason` is ``BUDGET`` once the black-box budget is spent, ``CONVERGED`` when
    (w*, theta*) stopped changing; after ``max_rounds`` rounds, the last black-box step's own reason
    (``CONVERGED``, ``NO_IMPROVEMENT``, ``NO_SAFE_POINT``) when it stopped without moving theta*,
    else ``MAX_ROUNDS``; :attr:`stop_detail` says which loop stopped, in words; ``NO_SAFE_POINT``
    when the demonstration failed, ``ERROR`` after any other exception; None while the run goes on.
    """

    def __init__(self, task: Task, optimizer_factory: OptimizerFactory, config: CORLConfig = CORLConfig(),
                 *, seed: int = 0) -> None:
        self.task = task
        self.optimizer_factory = optimizer_factory
        self.config = config
        self.seed = int(seed)
        self.history: list[tuple[Proposal, Outcome]] = []
        self.J_history: list[tuple[int, float]] = []  # (trial index, J(w)) of every rolled-out w
        self.unrealisable = 0
        self.rl_trials = 0  # black-box trials so far (the budget max_rl_trials counts these)
        self.known_failures = 0  # step-2 thetas whose realisation had already failed: told, not rolled out
        self.failed_w: list[np.ndarray] = []  # w of every failed trial: never proposed again
        self.eps_max = config.eps_max  # current trust region of step 1, halved at each failed step
        self.rounds = 0
        self._end: StopReason | None = None
        self.rl_stop_reason: StopReason | None = None  # why the latest black-box step (step 2) stopped
        self.stop_detail = ""  # which loop of Algorithm 1 stopped the run, in words (see stop_reason)
        self.optimizers: list[BlackBoxOptimizer] = []
        self._best: Best | None = None
        # h(w0, theta0) ~ 0 is checked here, before anything can be rolled out
        self._demonstration = check_demonstration(task, tolerance=config.demo_tolerance)
        self._pending: Proposal | None = None
        self._asked = False  # the pending trial was handed out by ask(): only then may tell() answer it
        self._finished = False
        self.start_step = "demonstration"  # the step name of trial 0 ("skill" when a skill's policy starts it)
        self.speculative = False  # see _speculate; pays only when rollouts leave the GIL free (corl.tasks.worker)
        self._speculation: _Speculation | None = None
        self._gen: Generator[Proposal, Outcome, None] = self._algorithm()

    # -- ask / tell ----------------------------------------------------------------------------
    def ask(self) -> Proposal:
        """The next trial to execute. A trial asked but not told is returned again."""
        if self._pending is not None:
            self._asked = True
            return self._pending
        if self._finished:
            raise StateError("CORL has finished; read .best")
        try:
            self._pending = next(self._gen)
        except StopIteration:
            self._finished = True
            raise StateError("CORL has finished; read .best") from None
        self._asked = True
        return self._pending

    def tell(self, outcome: Outcome) -> None:
        """Record the outcome of the trial handed out by the last :meth:`ask` (each trial is told once)."""
        self.settle()  # the speculation shares the task's caches: nothing touches the task before it ends
        if self._pending is None or not self._asked:  # the next trial is worked out at tell(), not yet asked
            raise StateError("tell() without a pending ask(): call ask() first, run its trial, then tell its outcome")
        if not isinstance(outcome, Outcome):
            raise InputError(f"tell() needs a corl.Outcome, got {type(outcome).__name__}")
        proposal = self._pending
        self._pending, self._asked = None, False
        self.history.append((proposal, outcome))
        if not outcome.success:
            self.failed_w.append(np.array(proposal.w, dtype=float))
        try:
            self.J_history.append((proposal.index, cost_of(self.task, proposal.w)))
            self._pending = self._gen.send(outcome)
        except StopIteration:
            self._finished = True
        except Exception:
            self._finished = True  # the trial is recorded in history; the run cannot go on (J's task code too)
            raise

    def settle(self) -> None:
        """Wait for the speculative computation, if one runs (its result or error stays with it)."""
        if self._speculation is not None:
            self._speculation.join()

    def _speculate(self, fn, *args, **kwargs) -> "_Speculation | None":
        """Start ``fn(*args, **kwargs)`` in a thread when :attr:`speculative`, else None: the call the
        code after a step-1 or phase trial's yield would make, run while the trial is rolled out.
        :meth:`tell` joins it first; the generator takes its result (or error) where the sequential
        code would make the call, or drops it (a failure): the same trials, bit for bit."""
        if not self.speculative:
            return None
        self._speculation = _Speculation(fn, args, kwargs)
        return self._speculation

    def _resumed(self) -> None:
        """After a yield: the speculation, if any, has ended (tell joins it; joined again here)."""
        self.settle()
        self._speculation = None

    @property
    def done(self) -> bool:
        """True once Algorithm 1 has stopped ("until no change in (w*, theta*)")."""
        return self._finished

    @property
    def stop_reason(self) -> StopReason | None:
        """Why Algorithm 1 stopped (see the class notes), or None while it runs."""
        if not self._finished:
            return None
        if self.rl_trials >= self.config.max_rl_trials:
            return StopReason.BUDGET
        return self._end or StopReason.ERROR  # finished without a decision: an exception ended it

    @property
    def best(self) -> Best | None:
        """The best successful policy ``(w*, theta*)`` with its return and J, or None."""
        return self._best

    @property
    def best_observed(self) -> tuple[Proposal, Outcome] | None:
        """The successful trial with the highest *reading* (the luckiest under noise), or None; not what
        to deploy: that is :attr:`best`, the learner's best, shown beside it under this name."""
        return best_observed(self.history)

    def run(self, task: Task | None = None, *, max_trials: int | None = None,
            callback: Callable[[Proposal, Outcome], None] | None = None) -> Best | None:
        """Convenience loop: ask, ``task.rollout(w)``, tell, until done or ``max_trials``."""
        drive(self, task or self.task, max_trials=max_trials, callback=callback)
        return self.best

    # -- Algorithm 1 ---------------------------------------------------------------------------
    def _proposal(self, w: np.ndarray, theta: np.ndarray, step: str, *, again: bool = False) -> Proposal:
        if not again and self.failed_before(w):  # a guard: every step checks failed_before first
            raise StateError(f"internal error: the learner was about to propose a w that already failed ({step})")
        return Proposal(index=len(self.history), w=w, theta=theta, step=step, round=self.rounds)

    def _stays(self, w_next, w_i) -> bool:
        """A chain's step (step 1, phase) ends: ``w_next`` moved under eps_w, lowers J by less than the
        fraction ``min_J_decrease``, or failed before (when rolled out)."""
        cfg = self.config
        if np.linalg.norm(w_next - w_i) < cfg.eps_w or (cfg.rollout_every_step and self.failed_before(w_next)):
            return True
        return cfg.min_J_decrease > 0.0 and cost_of(self.task, w_next) > (1.0 - cfg.min_J_decrease) * cost_of(self.task, w_i)

    def failed_before(self, w: np.ndarray) -> bool:
        """True when ``w`` (n,) is within ``eps_w`` of the w of a failed trial (the same policy)."""
        w = np.asarray(w, dtype=float)
        return any(np.linalg.norm(w - f) < self.config.eps_w for f in self.failed_w)

    def _algorithm(self) -> Iterator[Proposal]:
        task, cfg = self.task, self.config
        w0, theta0 = self._demonstration.w, self._demonstration.theta  # checked in __init__
        outcome = yield self._proposal(w0, theta0, self.start_step)
        # a failed demonstration may be one wrong reading: try it again (a skill's start in a new scene is not:
        # corl.contexts goes on from its next start, which costs no repeat of a motion that may truly fail)
        for _ in range(cfg.start_retries if self.start_step == "demonstration" else 0):
            if outcome.success:
                break
            outcome = yield self._proposal(w0, theta0, self.start_step, again=True)
        if outcome.success:  # a demonstration that succeeded is no failed w, whatever an earlier reading said
            self.failed_w = [f for f in self.failed_w if np.linalg.norm(w0 - f) >= cfg.eps_w]
        if not outcome.success:
            self._end = StopReason.NO_SAFE_POINT
            raise DemonstrationFailedError(
                f"the demonstration of task '{task.name}' failed (S(theta0) = 0, info {dict(outcome.info)}); "
                "Algorithm 1 needs a successful demonstration: re-record it or check the success criterion"
            )
        # Alg. 1: Initialize (w*, theta*) = (w0, theta0)
        w_star, theta_star, r_star = w0, theta0, float(outcome.return_)
        self._best = Best(w_star, theta_star, r_star, cost_of(task, w_star))
        data: list[tuple[np.ndarray, Outcome]] = [(theta0, outcome)]
        for self.rounds in range(cfg.max_rounds):
            w_before, theta_before = w_star, theta_star
            # -- 1) Optimization (Sec. VI): trust-region steps on J with theta* fixed (Eq. 8) ----
            w_star, r_star = yield from self._optimization(w_star, theta_star, r_star)
            # -- 2) Black-box reinforcement learning over theta (Sec. VII) -------------------------
            if not cfg.reuse_data:
                data = []
            data = [d for d in data if not np.array_equal(d[0], theta_star)] + [(theta_star, Outcome(True, r_star))]
            w_star, theta_star, r_star, data = yield from self._reinforcement(w_star, theta_star, r_star, data)
            # Alg. 1: until no change in policy parameter (w*, theta*)
            if np.linalg.norm(w_star - w_before) < cfg.eps_w and np.array_equal(theta_star, theta_before):
                self._end = StopReason.CONVERGED
                self.stop_detail = f"(w*, theta*) stopped changing in round {self.rounds}"
                break
        else:
            self._end, self.stop_detail = self._rounds_end(theta_star, theta_before)

    def _rounds_end(self, theta_star, theta_before) -> tuple[StopReason, str]:
        """Why the last round ended the run: its black-box step's own rule if theta* did not move, else MAX_ROUNDS."""
        rounds = self.config.max_rounds
        reason = self.rl_stop_reason
        own = (StopReason.CONVERGED, StopReason.NO_IMPROVEMENT, StopReason.NO_SAFE_POINT)
        if reason in own and np.array_equal(theta_star, theta_before):
            return reason, (f"the black-box step of round {rounds - 1} (the last of max_rounds={rounds}) stopped: "
                            f"{reason.value}, theta* unchanged")
        return StopReason.MAX_ROUNDS, f"Algorithm 1 ran all max_rounds={rounds} rounds; theta* still moved in the last"

    def _optimization(self, w_star, theta_star, r_star):
        task, cfg = self.task, self.config
        problem = motion_problem(task, theta_star)  # the task's banded problem (SQP) when it gives one
        w_star, r_star, w_i, failed = yield from self._trajectory_steps(problem, w_star, theta_star, r_star)
        if failed:
            return w_star, r_star
        task_star = self.task  # the task whose constraints w* satisfies (phase steps may re-time it)
        if cfg.max_phase_steps > 0 and getattr(task, "spline", None) is not None:
            w_star, r_star, w_i = yield from self._phase(problem, w_star, r_star, w_i, theta_star)
        if not cfg.rollout_every_step and not np.array_equal(w_i, w_star):
            if self.failed_before(w_i):
                self.task = task_star
                return w_star, r_star
            outcome = yield self._proposal(w_i, theta_star, "optimization")
            if outcome.success:
                w_star, r_star = w_i, float(outcome.return_)
                self._best = Best(w_star, theta_star, r_star, cost_of(task, w_star))
            else:
                self.eps_max /= 2.0
                self.task = task_star
        return w_star, r_star

    def _trajectory_steps(self, problem, w_star, theta_star, r_star):
        """Eq. 8's steps from w* (theta* fixed): (w*, R*, the last step w(i), whether a rollout failed)."""
        task, cfg = self.task, self.config
        w_i = w_star
        ahead: _Speculation | None = None  # solve() from w_i, started while w_i was rolled out
        for step in range(cfg.max_optimization_steps):
            # Eq. 8: w(i+1) = argmin J(w) s.t. h(w, theta*) = 0, ||w - w(i)|| < eps_max
            result = ahead.result() if ahead is not None else solve(problem, w_i, center=w_i, radius=self.eps_max,
                                                                    config=cfg.solver)
            ahead, w_next = None, result.w
            if self._stays(w_next, w_i):  # until ||w(i+1) - w(i)|| < eps_w; a step that failed is never run again
                break
            w_i = w_next
            if cfg.rollout_every_step:
                proposal = self._proposal(w_i, theta_star, "optimization")
                if step + 1 < cfg.max_optimization_steps:  # the next solve starts from w_i, whatever the outcome
                    ahead = self._speculate(solve, problem, w_i, center=w_i, radius=self.eps_max, config=cfg.solver)
                outcome = yield proposal
                self._resumed()
                if not outcome.success:  # do not walk further into failure; later steps are smaller
                    self.eps_max /= 2.0
                    return w_star, r_star, w_i, True
                w_star, r_star = w_i, float(outcome.return_)  # set best w* if rollout successful
                self._best = Best(w_star, theta_star, r_star, cost_of(task, w_star))
        return w_star, r_star, w_i, False

    def _phase(self, problem, w_star, r_star, w_i, theta_star):
        """Sec. VI-B: phase steps (Eq. 10) with the geometry fixed, after the trajectory steps. Each
        re-times the path (trust region on the phase profile), re-fits the B-spline and projects it onto
        ``h = 0`` (Eq. 18); kept if it lowers J, rolled out like a trajectory step. A task with
        ``retimed(time_map)`` moves its contact instants with the phase and the learner continues with
        the re-timed task; without it, ``task.pinned_times`` keep their phase."""
        cfg = self.config
        candidate = self._phase_step(theta_star)
        J_i = cost_of(self.task, w_i)
        ahead: _Speculation | None = None  # the next phase step from w_i, started while w_i was rolled out
        for step in range(cfg.max_phase_steps):
            found = ahead.result() if ahead is not None else candidate(self.task, problem, w_i)
            ahead = None
            if found is None:
                break
            task, problem, w_next, J_next = found
            if J_next >= J_i or self._stays(w_next, w_i):
                break
            w_i, J_i = w_next, J_next
            if cfg.rollout_every_step:
                proposal = self._proposal(w_i, theta_star, "phase")
                if step + 1 < cfg.max_phase_steps:  # from the re-timed task, which holds on a success
                    ahead = self._speculate(candidate, task, problem, w_i)
                outcome = yield proposal
                self._resumed()
                if not outcome.success:
                    break
                w_star, r_star = w_i, float(outcome.return_)
                self._best = Best(w_star, theta_star, r_star, J_i)
            self.task = task  # the re-timed contacts hold from here on
        return w_star, r_star, w_i

    def _phase_step(self, theta_star):
        """One phase step from (task, problem, w_i): (task, problem, w, J), None to stop (see _phase)."""
        from corl.trajectory.phase import optimize_phase, retime

        movable = callable(getattr(self.task, "retimed", None))
        pinned = () if movable else tuple(getattr(self.task, "pinned_times", ()))

        def candidate(task, problem, w_i):
            phase = optimize_phase(task.spline, w_i, pinned_times=pinned)
            if not phase.cost_after < phase.cost_before:
                return None
            if movable:
                grid = np.linspace(0.0, task.spline.duration, phase.p.shape[0])
                T = task.spline.duration
                task = task.retimed(lambda t, p=phase.p: np.interp(np.asarray(t) / T, p, grid))
                problem = motion_problem(task, theta_star)
            retimed = retime(task.spline, w_i, phase.p, equalities=problem)
            if retimed.projection is not None and not feasible(retimed.projection, self.config.solver):
                return None
            return task, problem, retimed.w, cost_of(task, retimed.w)
        return candidate

    def _realised(self, w_star, theta_star, theta):
        """Eq. 18 at ``theta``: ``(w, None)`` to run, or ``(None, outcome)`` known (unrealisable, or failed before)."""
        result = realise(self.task, w_star, theta_star, theta, self.config.solver)
        if not result.feasible:
            self.unrealisable += 1
            return None, Outcome(False, None, {"unrealisable": True, "status": result.status})
        if self.failed_before(result.w):
            self.known_failures += 1
            return None, Outcome(False, None, {"known_failure": True})
        return result.w, None

    def _reinforcement(self, w_star, theta_star, r_star, data):
        task, cfg = self.task, self.config
        rng = np.random.default_rng([self.seed, self.rounds])
        optimizer = self.optimizer_factory(task.theta_bounds, theta_star.copy(), rng)
        if hasattr(optimizer, "recheck_failures"):  # a failed w is never run again here: no repeat to ask for
            optimizer.recheck_failures = False
        self.optimizers.append(optimizer)
        for theta, outcome in data:  # Alg. 1: Initialize D
            optimizer.tell(theta, outcome)
        candidates: list[tuple[np.ndarray, np.ndarray, float]] = []
        previous = theta_star
        # the budget spans the run: max_rl_trials black-box trials over all rounds (CORLConfig)
        while self.rl_trials < cfg.max_rl_trials and not optimizer.done:
            theta = optimizer.ask()  # theta(d+1) = argmax_theta a(theta, D), decided when done was read
            self.rl_trials += 1
            w, outcome = self._realised(w_star, theta_star, theta)
            if outcome is None:
                outcome = yield self._proposal(w, theta, "reinforcement")
                if outcome.success:
                    candidates.append((w, theta, float(outcome.return_)))
            optimizer.tell(theta, outcome)  # add datapoint to D
            data.append((theta, outcome))
            if cfg.theta_step_stop and np.linalg.norm(theta - previous) < cfg.eps_theta:
                break  # until ||theta(d+1) - theta(d)|| < eps_theta
            previous = theta
        return self._step_end(optimizer, candidates, w_star, theta_star, r_star, data)

    def _step_end(self, optimizer, candidates, w_star, theta_star, r_star, data):
        """The end of a black-box step: why it stopped, and theta* from its ``candidates`` (w, theta, R)."""
        cfg, task = self.config, self.task
        if optimizer.done:
            self.rl_stop_reason = optimizer.stop_reason
        else:  # the learner stopped it: the run's budget, or Alg. 1's ||theta(d+1) - theta(d)|| < eps_theta
            self.rl_stop_reason = StopReason.BUDGET if self.rl_trials >= cfg.max_rl_trials else StopReason.CONVERGED
        # set best theta* = argmax_{theta in D} R(theta) s.t. S(theta*) = 1
        posterior = getattr(optimizer, "learners_best", None)  # a method that models the noise: its posterior
        if posterior is not None:
            chosen = [c for c in candidates if np.array_equal(c[1], posterior.theta)]
            if chosen:  # the last trial at that theta (a repeat's w is the same projection)
                w_star, theta_star, r_star = chosen[-1]
            # the value: w*'s own reading +- one reading's noise (theta* chosen on g_R's posterior; g_R's mean at
            # theta* would mix in earlier w's readings: on the door, 0.49 at a w* that reads 0.57)
            self._best = Best(w_star, theta_star, r_star, cost_of(task, w_star), optimizer.noise_std_, r_star)
            return w_star, theta_star, r_star, data
        for w, theta, r in candidates:
            if r > r_star:
                w_star, theta_star, r_star = w, theta, r
        self._best = Best(w_star, theta_star, r_star, cost_of(task, w_star), reading=r_star)
        return w_star, theta_star, r_star, data
