"""The old home of the method registry, kept so that ``from corl.experiments.methods import
make_method`` goes on working: the registry lives in :mod:`corl.methods` now, below the run store
(:mod:`corl.session` builds learners by name and must not reach up into the experiments).

A package rather than a module so that the registry's file moved with ``git mv`` unchanged
(a merge carries edits of ``experiments/methods.py`` over to ``corl/methods.py``). Everything
:mod:`corl.methods` lists in ``__all__`` is re-exported, names added there included.
"""

from corl.methods import *  # noqa: F401,F403  (a compatibility alias: its whole content)
from corl.methods import __all__  # noqa: F401
