"""One skill, many scenes: learning a skill across contexts (beyond the paper, Sec. IX).

A context ``c`` is what the robot measures before a trial and cannot choose (a door's pose, a
handle's height). A task gives contexts through :class:`corl.problem.HasContexts`. Then:

* :class:`ContextualCORL` learns in one scene, started from what the other scenes taught and
  with g_R, g_S over ``(theta, c)`` (:mod:`corl.contexts.models`);
* :class:`Skill` answers ``policy(c)`` for any scene of the box, with no trial;
* :func:`learned` reads both from a run store, where each run records its context.
"""

from corl.contexts.learn import ContextualCORL, StartedTask, contextual_factory, plain_learner
from corl.contexts.models import ContextData, ContextSlice, ContextualModels, joint_bounds
from corl.contexts.skill import P_MIN, Anchor, Policy, Skill, context_task
from corl.contexts.stored import failed_motions, learned, run_context, snapshot

__all__ = ["ContextualCORL", "StartedTask", "contextual_factory", "plain_learner", "ContextData", "ContextSlice",
           "ContextualModels", "joint_bounds", "P_MIN", "Anchor", "Policy", "Skill", "context_task", "learned",
           "run_context", "snapshot", "failed_motions"]
