"""A learned skill for any scene in the context box: ``Skill.policy(c)``, with no trial.

What a skill holds: the task (with contexts, :class:`corl.problem.HasContexts`), the black-box
data of every context learned (:class:`~corl.contexts.models.ContextData`) and one anchor per
learned context, its best policy ``(w*, theta*)``. For a context ``c`` it answers

1. theta: the maximiser of the expected return at ``c``, ``p(theta, c) R_mean(theta, c) + (1 - p)
   R_fail``, with g_S's success probability ``p`` and g_R's posterior mean over ``(theta, c)``, and a
   failure worth ``R_fail``, the lowest return seen less the returns' spread (a failure is worse than
   any success). No threshold on ``p``: its scale depends on the task (a pessimistic prior mean
   makes a wide safe set read 0.8-0.98 inside), the trade-off between return and risk does not;
2. w: the nearest anchor's ``w*`` (distance of contexts in the unit box) realised in scene ``c``
   at that theta by Eq. 18 (:func:`corl.realise.realise`), then improved by step 1 of
   Algorithm 1 run to convergence (Eq. 8 without a trust region: J and h are analytic, so this
   needs no rollout);
3. how sure: ``p_success`` and the posterior mean and std of R there.

A context outside the box is refused (:class:`~corl.errors.InputError`, one line).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from corl import checks
from corl.contexts.models import Anchor, ContextData, ContextualModels
from corl.errors import InputError
from corl.problem import Bounds, Task, check_theta, context_of
from corl.learner import cost_of
from corl.realise import feasible, motion_problem, realise
from corl.trajectory.solver import SolverConfig, solve

__all__ = ["Anchor", "Policy", "Skill", "P_MIN", "context_task", "scene_of"]

#: The skill knows a scene when its start there succeeds with at least this probability; then learning
#: in the scene refines it (:data:`corl.contexts.learn.IN_A_NEW_SCENE`), else it explores as in one scene
P_MIN = 0.95
_CANDIDATES = 512  # random thetas per policy, besides the data and the anchors


def context_task(task: Task) -> Task:
    """``task`` if it has contexts, else one :class:`InputError` saying what to add."""
    if context_of(task) is None:
        raise InputError(f"task '{getattr(task, 'name', '?')}' has no contexts: give it context_bounds, context and "
                         "with_context(c) (see corl.problem.HasContexts and the README's 'One skill, many scenes')")
    return task


def scene_of(task: Task, c) -> Task:
    """``task.with_context(c)``, checked: a task (:func:`corl.problem.check_task`) in context ``c``
    whose theta box is the task's (theta keeps its meaning); else one :class:`InputError`."""
    from corl.errors import CorlError
    from corl.problem import check_task

    name = getattr(task, "name", "?")
    c = np.asarray(c, dtype=float)
    try:
        scene = task.with_context(c)
    except CorlError:
        raise
    except Exception as exc:  # the task's own code
        raise InputError(f"task '{name}': with_context({c.tolist()}) raised {type(exc).__name__}: {exc}; fix the "
                         "task (call it in Python to see the traceback)") from None
    where = f"task '{name}': with_context({c.tolist()})"
    if scene is None:
        raise InputError(f"{where} returned None; it must return the task in that scene (corl.problem.HasContexts)")
    check_task(scene, where)
    got = context_of(scene)
    if got is None or got.shape != c.shape or not np.allclose(got, c, rtol=0.0, atol=1e-12 * (1.0 + np.abs(c).max())):
        raise InputError(f"{where} returned a task in context {None if got is None else got.tolist()}; its context "
                         "must be the one asked for (corl.problem.HasContexts)")
    if not (np.array_equal(scene.theta_bounds.lower, task.theta_bounds.lower)
            and np.array_equal(scene.theta_bounds.upper, task.theta_bounds.upper)):
        raise InputError(f"{where} changed theta_bounds; theta keeps its meaning and its box across contexts")
    return scene


@dataclass(frozen=True, eq=False)
class Policy:
    """What :meth:`Skill.policy` proposes for ``context``.

    ``w`` (n,) the motion, ``theta`` (m,) what it realises; ``p_success`` g_S's success probability
    there; ``R_mean``, ``R_std`` g_R's posterior; ``J`` the analytic cost; ``nearest`` the anchor
    context its motion was realised from; ``feasible``: ``h(w, theta) = 0`` holds in this scene
    (always: :meth:`Skill.policy` refuses a scene where no motion realises its theta).
    """

    context: np.ndarray
    w: np.ndarray
    theta: np.ndarray
    p_success: float
    R_mean: float
    R_std: float
    J: float
    nearest: np.ndarray
    feasible: bool

    def __iter__(self):  # w, theta, p_success, R_mean = skill.policy(c)
        return iter((self.w, self.theta, self.p_success, self.R_mean))


class Skill:
    """One skill for every scene of the context box.

    Parameters
    ----------
    task : a task with contexts (the one the demonstration was recorded in, or any of its family).
    data : the black-box trials of every context learned.
    anchors : the best policy of each learned context (at least one).
    p_min : the success probability from which the skill counts as knowing a scene (:data:`P_MIN`).
    solver : the motion solver's settings (Eq. 18 and step 1).
    """

    def __init__(self, task: Task, data: ContextData, anchors: list[Anchor], *, p_min: float = P_MIN,
                 solver: SolverConfig = SolverConfig(), seed: int = 0) -> None:
        self.task = context_task(task)
        self.context_bounds: Bounds = task.context_bounds
        self.theta_bounds: Bounds = task.theta_bounds
        m, k = self.theta_bounds.dim, self.context_bounds.dim
        if not isinstance(data, ContextData) or data.theta.shape[1] != m or data.context.shape[1] != k:
            raise InputError(f"a skill's data must be a ContextData with {m} theta and {k} context columns for task "
                             f"'{task.name}'")
        if not anchors:
            raise InputError("a skill needs at least one learned context: run corl in one context first "
                             "(corl run TASK --context ...)")
        sizes = set()
        for a in anchors:
            if not isinstance(a, Anchor) or np.shape(a.theta) != (m,) or np.shape(a.context) != (k,) \
                    or np.ndim(a.w) != 1 or not self.context_bounds.contains(a.context):
                raise InputError(f"a skill's anchors must be Anchors with theta ({m},), a context ({k},) inside the box "
                                 f"and a motion w (n,) for task '{task.name}'")
            sizes.add(np.size(a.w))
        if len(sizes) > 1:
            raise InputError(f"a skill's anchors have motions of {sorted(sizes)} parameters; one task has one size")
        p_min = checks.number("Skill p_min", p_min, low=0.0, low_open=True)
        if not p_min < 1.0:
            raise InputError(f"Skill p_min is a probability in (0, 1), got {p_min!r}")
        self.data, self.anchors, self.p_min, self.solver = data, list(anchors), float(p_min), solver
        self.seed = checks.integer("Skill seed", seed, low=0)

    # -- the models ----------------------------------------------------------------------------
    @cached_property
    def models(self):
        """g_R (on successes) and g_S (on every trial) over ``(theta, c)``, fitted once, as a contextual
        run fits them (:class:`~corl.contexts.models.ContextualModels`, every trial a prior one)."""
        empty = np.empty((0, self.theta_bounds.dim))
        fits = ContextualModels(self.theta_bounds, self.context_bounds, self.data, self.anchors[0].context)
        regression = fits.regression(empty, np.empty(0))
        fits.classifier(empty, np.empty(0, dtype=bool))
        return (None if regression is None else fits.last_regression), fits.last_classifier

    def check_context(self, c) -> np.ndarray:
        """``c`` as a point (k,) of the context box, or one :class:`InputError` naming the box."""
        try:
            return check_theta(c, self.context_bounds, task=getattr(self.task, "name", "task"), what="context")
        except InputError as exc:
            raise InputError(f"{exc}; the skill learned this box only, so it cannot say what to do there") from None
        except (TypeError, ValueError):
            k = self.context_bounds.dim
            raise InputError(f"a context must be {k} number{'s' if k > 1 else ''}, got {c!r:.60}") from None

    def nearest(self, c) -> Anchor:
        """The anchor whose context is nearest ``c`` in the unit box."""
        u = self.context_bounds.to_unit(np.asarray(c, dtype=float))
        dist = [float(np.linalg.norm(self.context_bounds.to_unit(a.context) - u)) for a in self.anchors]
        return self.anchors[int(np.argmin(dist))]

    def predict(self, theta, c) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``p_success``, ``R_mean``, ``R_std`` at thetas (s, m) in context ``c`` (k,); each (s,)."""
        theta = np.asarray(theta, dtype=float).reshape(-1, self.theta_bounds.dim)
        X = np.hstack([theta, np.broadcast_to(np.asarray(c, dtype=float), (len(theta), self.context_bounds.dim))])
        regression, classifier = self.models
        p = classifier.predict_proba(X)
        if regression is None:
            return p, np.full(len(X), np.nan), np.full(len(X), np.nan)
        mu, var = regression.predict(X)
        return p, mu, np.sqrt(np.maximum(var, 0.0))

    def choose_theta(self, c) -> np.ndarray:
        """The theta to try at ``c``: the highest expected return, a failure counted as :attr:`failure_return`
        (module docstring)."""
        c = self.check_context(c)
        rng = np.random.default_rng([self.seed, 7])
        cand = np.vstack([self.data.theta, [a.theta for a in self.anchors],
                          self.theta_bounds.from_unit(rng.random((_CANDIDATES, self.theta_bounds.dim)))])
        near = self.nearest(c).theta
        local = near + 0.05 * self.theta_bounds.width * rng.standard_normal((_CANDIDATES // 2, self.theta_bounds.dim))
        cand = np.vstack([cand, self.theta_bounds.clip(local)])
        p, mu, _ = self.predict(cand, c)
        if not np.all(np.isfinite(mu)):  # no success anywhere yet: the surest theta
            return cand[int(np.argmax(p))].copy()
        score = p * mu + (1.0 - p) * self.failure_return
        return cand[int(np.argmax(score))].copy()

    @cached_property
    def failure_return(self) -> float:
        """What a failure is worth to :meth:`choose_theta`: below every return seen, by their spread."""
        ok = self.data.success & np.isfinite(self.data.returns)
        r = self.data.returns[ok]
        if r.size == 0:
            return 0.0
        spread = float(np.std(r)) if r.size > 1 else 0.0
        return float(np.min(r)) - (spread if spread > 0 else max(1.0, abs(float(np.min(r)))))

    # -- the motion ----------------------------------------------------------------------------
    def motion(self, c, theta, anchor: Anchor | None = None) -> tuple[np.ndarray, bool]:
        """``w`` realising ``theta`` in scene ``c``: the anchor's ``w*`` by Eq. 18, then step 1 to
        convergence; ``(w, feasible)``."""
        c = self.check_context(c)
        theta = check_theta(theta, self.theta_bounds, task=self.task.name)
        anchor = self.nearest(c) if anchor is None else anchor
        scene = scene_of(self.task, c)
        if np.array_equal(anchor.context, c) and np.array_equal(anchor.theta, theta):
            return anchor.w.copy(), True  # a learned scene at its theta*: the motion that ran there
        done = realise(scene, anchor.w, anchor.theta, theta, self.solver)
        if not done.feasible:
            return done.w, False
        result = solve(motion_problem(scene, theta), done.w, config=self.solver)
        if feasible(result, self.solver) and cost_of(scene, result.w) <= cost_of(scene, done.w):
            return result.w, True
        return done.w, True

    def policy(self, c) -> Policy:
        """The motion to execute in context ``c``, its theta and how sure the skill is (no trial).

        Refuses (:class:`InputError`) a context outside the box and a scene where neither the chosen
        theta nor the nearest anchor's can be realised from the anchor's motion (Eq. 18)."""
        c = self.check_context(c)
        anchor = self.nearest(c)
        theta = self.choose_theta(c)
        w, ok = self.motion(c, theta, anchor)
        if not ok:  # Eq. 18 cannot reach this theta from the anchor: the anchor's own theta
            theta = anchor.theta.copy()
            w, ok = self.motion(c, theta, anchor)
        if not ok:
            raise InputError(f"no motion realises theta {np.array2string(theta, precision=4)} in context "
                             f"{np.array2string(c, precision=4)} from the nearest learned scene's (Eq. 18 stays "
                             "infeasible): the scene is out of the skill's reach; learn it from its own demonstration")
        p, mu, sd = self.predict(theta[None], c)
        return Policy(c, w, theta, float(p[0]), float(mu[0]), float(sd[0]), cost_of(scene_of(self.task, c), w),
                      anchor.context.copy(), ok)

    # -- from a store --------------------------------------------------------------------------
    @classmethod
    def load(cls, store, task: Task, **kw) -> "Skill":
        """The skill learned in a run store (a path or an open :class:`corl.store.RunStore`): every run of
        ``task`` in it, each in its context (:func:`corl.contexts.stored.learned`)."""
        from corl.contexts.stored import learned

        data, anchors = learned(store, context_task(task))
        return cls(task, data, anchors, **kw)

    def __repr__(self) -> str:
        return (f"Skill(task={self.task.name!r}, contexts={len(self.anchors)}, trials={len(self.data)}, "
                f"p_min={self.p_min})")
