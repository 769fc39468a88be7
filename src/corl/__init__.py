"""corl: Combined Optimization and Reinforcement Learning (Englert & Toussaint, RSS 2016).

A manipulation skill is learned from one demonstration: motion optimization improves the
analytic cost ``J(w)`` of a trajectory (:mod:`corl.trajectory`), and a safe black-box
optimizer (:mod:`corl.optimizers`) improves the unknown return ``R(theta)`` of the few task
parameters ``theta`` while avoiding failures ``S(theta) = 0``. :class:`corl.learner.CORL`
(Algorithm 1) alternates the two and speaks ``ask`` / ``tell`` like every baseline.

The packages, from the lowest layer up (a module imports only its own layer and those before
it, with no import cycles: ``tools/check_layers.py`` declares the order and ``make test`` checks it):

* :mod:`corl.errors`, :mod:`corl.numerics`, :mod:`corl.problem`: exceptions, safe numerics, the
  problem of Eq. 2-5 and the records a learning loop exchanges;
* :mod:`corl.trajectory`: B-splines, k-order Markov features, the Gauss-Newton solver (Eq. 8)
  and the projection of Eq. 18;
* :mod:`corl.gp`, :mod:`corl.acquisition`, :mod:`corl.optimizers`, :mod:`corl.policies`:
  Gaussian processes, PI / UCB / PIBU, the black-box methods, DMPs;
* :mod:`corl.mujoco`: a MuJoCo kit for any robot (features of Eq. 6, IK, rollouts, video);
* :mod:`corl.realise`: Eq. 18 with a task (realise a theta from ``w*``), the demonstration's check;
* :mod:`corl.loop`, :mod:`corl.learner`, :mod:`corl.direct`: the ask / roll out / tell loop,
  CORL and the methods over ``w``;
* :mod:`corl.settings`, :mod:`corl.methods`: the settings a task gives (``MethodSettings`` and
  the configs) and the methods of Fig. 1 by name (``make_method``);
* :mod:`corl.tasks`: the synthetic benchmark and the simulated PR2 door;
* :mod:`corl.store`, :mod:`corl.contexts`, :mod:`corl.session`: the run store, one skill across
  scenes (``corl.Skill.load(store, task).policy(c)``) and resumable runs;
* :mod:`corl.experiments`: the studies of Fig. 1 and Fig. 3, tables, figures, reports, sweeps;
* :mod:`corl.progress`, :mod:`corl.arguments`, :mod:`corl.cli`: the ``corl`` command.

The safe optimizer on its own (no trajectory, just a box and a start), loaded on first use so
that ``import corl`` stays light::

    result = corl.optimize(f, (lower, upper), start, method="PIBU", budget=40)
    opt = corl.make_optimizer("PIBU", (lower, upper), start, budget=40)   # ask / tell / done / stop_reason

``docs/index.md`` in the repository says how to build this reference (``make docs``).

On a machine without a display, importing corl sets ``MUJOCO_GL`` to an offscreen backend that
loads (EGL, else OSMesa) unless it is set already, before anything imports MuJoCo
(:mod:`corl.offscreen`): videos render on servers and clusters as on a desktop.
"""

from __future__ import annotations

import importlib

from corl import offscreen as _offscreen
from corl._version import __version__  # the release (the distribution is corl-skills on PyPI)

_offscreen.choose()

_LAZY = {  # public name -> module that defines it
    "optimize": "corl.loop",
    "OptimizeResult": "corl.loop",
    "make_optimizer": "corl.optimizers.registry",
    "register_optimizer": "corl.optimizers.registry",
    "OptimizerSettings": "corl.optimizers.registry",
    "SEIBConfig": "corl.acquisition.safe_ei",
    "OPTIMIZERS": "corl.optimizers.registry",
    "StopReason": "corl.optimizers.base",
    "Bounds": "corl.problem",
    "Outcome": "corl.problem",
    "Skill": "corl.contexts",
    "ContextualCORL": "corl.contexts",
}

# no __all__: pdoc follows a package's __all__, and corl's reference walks every submodule


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'corl' has no attribute '{name}'")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
