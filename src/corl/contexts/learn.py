"""Learning in one context with what every other context taught: :class:`ContextualCORL`.

Algorithm 1 runs unchanged in scene ``c`` (``task.with_context(c)``), with two differences:

* it starts from the skill's policy for ``c`` (:meth:`corl.contexts.Skill.policy`) instead of
  the demonstration, so its first trial is already the learned motion realised in this scene;
* its black-box step fits g_R and g_S over ``(theta, c)`` on the trials of every context
  (:class:`~corl.contexts.models.ContextualModels`) and proposes with SEIB at ``c``, keeping its
  safety rules (a safe start first, never a theta without a success probability in the band).

When the start itself fails, the failure joins the data and the next start is tried: the skill's
policy again, now knowing that failure (a theta at or next to it is never tried again), then the
scene's own demonstration when the task gives one that satisfies h there. A motion that failed in
the scene before (in this run or an earlier one, ``failed``) is never proposed again. The learner speaks ask/tell like :class:`CORL`;
its trials are numbered across starts.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from corl.acquisition.safe_ei import SEIBTuning
from corl.contexts.guard import SceneGuard
from corl.contexts.models import ContextData, ContextualModels
from corl import checks
from corl.contexts.skill import Skill, context_task, scene_of
from corl.errors import CorlError, DemonstrationFailedError, InputError, StateError
from corl.learner import CORL, cost_of
from corl.loop import drive
from corl.optimizers.base import ANSWER_TOLERANCE, StopReason
from corl.problem import Demonstration, Outcome, Proposal, Task, context_of
from corl.realise import check_demonstration

__all__ = ["ContextualCORL", "StartedTask", "contextual_factory", "plain_learner", "IN_A_NEW_SCENE"]

#: SEIB's settings in a scene learned from others (see contextual_factory): the skill's start is
#: already near the scene's optimum, so the black-box step refines it. It trusts its gate at once
#: (other scenes gave the data), never looks far (their valleys were crossed already) and proposes
#: only where g_S is as sure as the skill's own start (band [0.85, 0.95) instead of [0.55, 0.7),
#: inner region from :data:`corl.contexts.skill.P_MIN`). On six door scenes held out from the bench
#: (a skill of 8 scenes, 40 trials each), failures per scene: 9.3 with SEIB's defaults, 3.3 with the
#: band [0.7, 0.85), 0.8 with this one. Its EI margin is SEIB's own (1 % of the returns' spread): a
#: margin of 10 % stopped the first black-box step at once in 8 of 8 switch scenes, at 0.98 of the
#: best, and it stops only when g_R's posterior, with its uncertainty, expects no such gain where
#: both g_S's allow a trial (corl.contexts.guard).
IN_A_NEW_SCENE = {"p_band": 0.85, "far": False,
                  "_tuning": SEIBTuning(trust_per_dim=0, p_inner=0.95, stop_value=1e-3)}

#: The scene's own g_S must allow every proposal too (corl.contexts.guard): p >= the band's lower
#: edge of learning there alone ("band"), or its inner region ("inner"); None: the joint models alone.
SCENE_GUARD = "band"


class StartedTask:
    """A task whose demonstration is replaced by a given start ``(w, theta)`` (every other member is the task's)."""

    def __init__(self, task: Task, start: Demonstration) -> None:
        self._task, self._start = task, start

    def demonstration(self) -> Demonstration:
        return Demonstration(np.array(self._start.w, dtype=float), np.array(self._start.theta, dtype=float))

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_task", "_start"):
            raise AttributeError(name)
        value = getattr(self._task, name)  # AttributeError when the task lacks it (optional members)
        if name == "retimed" and callable(value):  # a re-timed copy keeps the start
            return lambda time_map: StartedTask(value(time_map), self._start)
        return value


def contextual_factory(task: Task, settings, prior: ContextData, context, *, refine: bool = False):
    """``(bounds, theta_start, rng) -> optimizer``: SEIB at ``context`` on GPs over ``(theta, c)``.

    ``refine``: the start is the skill's, which predicted it to succeed with at least its ``p_min``
    (the skill knows this scene): SEIB refines it with :data:`IN_A_NEW_SCENE`. Otherwise (a scene
    the skill is unsure of, or a fallback start) SEIB runs with the task's settings, as in one scene.
    """
    from corl.optimizers.safe import SAFE_BO_CONFIG, SafeBOOptimizer

    seib = settings.optimizer_settings().seib
    here = np.all(prior.context == np.asarray(context, dtype=float).reshape(1, -1), axis=1)
    others = len(prior) > int(np.sum(here))  # another scene's data: the joint models may mislead here
    guard_p = seib.p_band if SCENE_GUARD == "band" else seib.p_inner
    if refine:
        seib = replace(seib, **IN_A_NEW_SCENE)
    if seib.far_lengthscale is not None:
        raise InputError("SEIBConfig.far_lengthscale is not supported across contexts; leave it None")
    regression = settings.regression
    classifier = settings.classifier
    rp = regression.priors
    cp = classifier.priors

    def build(bounds, x0, rng):
        opt = SafeBOOptimizer(bounds, SAFE_BO_CONFIG, seib, max_evals=2**62, seed=rng, start=x0)
        opt.models = ContextualModels(task.theta_bounds, task.context_bounds, prior, context,
                                      regression_priors=rp, classifier_priors=cp, prior_mean=classifier.prior_mean)
        if SCENE_GUARD is not None and others:
            opt.guard = SceneGuard(task.theta_bounds, regression, classifier, guard_p,
                                   (prior.theta[here], prior.success[here]))
        return opt

    return build


def plain_learner(task: Task, *, seed: int = 0, settings=None) -> CORL:
    """Algorithm 1 in the task's own context from its demonstration (the first context of a skill),
    with the same black-box step as every later context (SEIB on fitted GPs over ``(theta, c)``,
    with no other context's data yet)."""
    from corl.methods import settings_for

    task = context_task(task)
    settings = settings_for(task) if settings is None else settings
    m, k = task.theta_bounds.dim, task.context_bounds.dim
    factory = contextual_factory(task, settings, ContextData.empty(m, k), context_of(task))
    return CORL(task, factory, settings.corl, seed=seed)


class ContextualCORL:
    """Algorithm 1 in context ``c``, started from ``skill`` and learning over ``(theta, c)``.

    Parameters
    ----------
    task : a task with contexts (any member of its family).
    context : (k,) the scene to learn in, inside the box.
    skill : :class:`Skill` of the contexts learned so far.
    settings : :class:`corl.settings.MethodSettings` (default: the task's); its CORLConfig
        bounds the run, the GP priors come from its regression and classifier configs.
    seed : seeds the black-box step.
    failed : motions (n,) known to have failed in this scene (earlier runs there): never proposed again.

    Raises
    ------
    InputError : no start can be realised in the scene.
    """

    def __init__(self, task: Task, context, skill: Skill, *, settings=None, seed: int = 0, failed=()) -> None:
        from corl.methods import settings_for

        self.base = context_task(task)
        if not isinstance(skill, Skill):
            raise InputError(f"ContextualCORL needs a corl.Skill (Skill.load(store, task)), got {type(skill).__name__}")
        if skill.task.name != self.base.name:
            raise InputError(f"the skill was learned for task '{skill.task.name}', not '{self.base.name}'")
        self.skill = skill
        self.context = skill.check_context(context)
        self.scene = scene_of(self.base, self.context)
        self.settings = settings_for(self.scene) if settings is None else settings
        self.config = self.settings.corl
        self.seed = checks.integer("ContextualCORL seed", seed, low=0)
        self.history: list[tuple[Proposal, Outcome]] = []
        self.J_history: list[tuple[int, float]] = []
        self.known_failed = [np.asarray(w, dtype=float) for w in failed]  # this scene's failed motions
        self.starts_tried = 0
        self._starts = self._start_list()
        self._local = ContextData.empty(self.base.theta_bounds.dim, self.base.context_bounds.dim)
        self._offset = 0
        self._inner: CORL | None = None
        self._end: StopReason | None = None
        self._detail = ""
        self.start_kind = ""
        self.refining = False  # the black-box step refines the skill's start (IN_A_NEW_SCENE)
        if not self._next_start():
            raise InputError(f"no start can be realised in context {np.array2string(self.context, precision=4)}: "
                             "the skill's motion does not reach it and the scene gives no demonstration that "
                             "satisfies h there; record a demonstration in that scene")

    # -- the starts ----------------------------------------------------------------------------
    def _start_list(self):
        """Lazily: the skill's policy; after a failed start, the skill's policy again, knowing that
        failure (g_S moves it away); the scene's own demonstration."""
        def skill_policy():
            try:
                return self.skill.policy(self.context)
            except InputError:  # out of the skill's reach
                return None

        yield "skill", skill_policy

        def knowing():
            if not len(self._local):
                return None
            wiser = Skill(self.base, self.skill.data + self._local, self.skill.anchors, p_min=self.skill.p_min,
                          solver=self.skill.solver, seed=self.skill.seed)
            try:
                return wiser.policy(self.context)
            except InputError:
                return None

        yield "skill", knowing

        def own():
            try:
                return check_demonstration(self.scene, tolerance=self.config.demo_tolerance)
            except CorlError:  # no demonstration in that scene, or one that misses h
                return None
            except (AttributeError, NotImplementedError):
                return None

        yield "demonstration", own

    def failed_before(self, w) -> bool:
        """``w`` is within ``eps_w`` of a motion that failed in this scene (this run or an earlier one)."""
        w = np.asarray(w, dtype=float)
        fails = self.known_failed + [np.asarray(p.w, dtype=float) for p, o in self.history if not o.success]
        return any(f.shape == w.shape and np.linalg.norm(w - f) < self.config.eps_w for f in fails)

    def _next_start(self) -> bool:
        prior = self.skill.data + self._local
        for name, make in self._starts:
            start = make()
            if start is None or not getattr(start, "feasible", True):
                continue
            demo = Demonstration(np.asarray(start.w, dtype=float), np.asarray(start.theta, dtype=float))
            if self.failed_before(demo.w):
                continue  # this very motion failed already
            if any(np.all(np.abs(demo.theta - t) <= ANSWER_TOLERANCE * self.base.theta_bounds.width)
                   for t in self._local.theta):
                continue  # (nearly) the theta of a start that just failed
            self.start_kind = name
            self.starts_tried += 1
            self._offset = len(self.history)
            refine = name == "skill" and start.p_success >= self.skill.p_min
            self.refining = refine
            factory = contextual_factory(self.base, self.settings, prior, self.context, refine=refine)
            self._inner = CORL(StartedTask(self.scene, demo), factory, self.config, seed=self.seed)
            self._inner.start_step = name  # "skill" or "demonstration": what the robot is asked to run
            self._inner.failed_w.extend(self.known_failed)  # never proposed again (CORL.failed_before)
            self._inner.failed_w.extend(np.asarray(p.w, dtype=float) for p, o in self.history if not o.success)
            return True
        self._inner = None
        self._end = StopReason.NO_SAFE_POINT
        self._detail = f"every start failed in context {np.array2string(self.context, precision=4)}"
        return False

    # -- ask / tell ----------------------------------------------------------------------------
    def ask(self) -> Proposal:
        if self._inner is None:
            raise StateError("the contextual learner has finished; read .best")
        p = self._inner.ask()
        return replace(p, index=p.index + self._offset)

    def tell(self, outcome: Outcome) -> None:
        if self._inner is None:
            raise StateError("tell() without a pending ask(): the contextual learner has finished")
        inner = self._inner
        pending = inner._pending if inner._asked else None
        try:
            inner.tell(outcome)
        except DemonstrationFailedError:  # the start failed: learn from it and try the next start
            self._record(pending, outcome)
            self._local = self._local.add(pending.theta, self.context, False, None)
            self._next_start()
            return
        self._record(pending, outcome)

    def _record(self, proposal: Proposal, outcome: Outcome) -> None:
        proposal = replace(proposal, index=proposal.index + self._offset)
        self.history.append((proposal, outcome))
        self.J_history.append((proposal.index, cost_of(self.scene, proposal.w)))

    def run(self, task: Task | None = None, *, max_trials: int | None = None, callback=None):
        drive(self, task or self.scene, max_trials=max_trials, callback=callback)
        return self.best

    # -- results -------------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self._inner is None or self._inner.done

    @property
    def stop_reason(self) -> StopReason | None:
        if self._inner is None:
            return self._end
        return self._inner.stop_reason

    @property
    def stop_detail(self) -> str:
        return self._detail if self._inner is None else self._inner.stop_detail

    @property
    def best(self):
        return None if self._inner is None else self._inner.best

    @property
    def rl_trials(self) -> int:
        return 0 if self._inner is None else self._inner.rl_trials

    def __getattr__(self, name):  # unrealisable, known_failures, rounds, ... of the current CORL
        if name.startswith("_") or self.__dict__.get("_inner") is None:
            raise AttributeError(name)
        return getattr(self._inner, name)
