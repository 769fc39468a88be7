"""The method registry lives below the run store (corl/methods.py); its old path still imports."""

from __future__ import annotations

import numpy as np

import corl.experiments.methods as old
import corl.methods as methods
from corl.tasks.synthetic import SyntheticTask


def test_the_old_import_path_is_the_same_registry():
    assert set(old.__all__) == set(methods.__all__)
    for name in methods.__all__:
        assert getattr(old, name) is getattr(methods, name)


def test_every_method_builds_by_name_and_asks_for_the_demonstration_first():
    w0 = SyntheticTask.random_start(np.random.default_rng(0))
    for name in methods.METHODS:
        proposal = methods.make_method(name, SyntheticTask(w0), seed=0).ask()
        assert proposal.index == 0 and np.array_equal(proposal.w, w0), name
