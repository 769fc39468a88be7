"""Shared by the black-box optimizer tests: a 2-D quadratic return and the ask/tell loop."""

from __future__ import annotations

import numpy as np

from corl.problem import Bounds, Outcome

UNIT2 = Bounds(np.zeros(2), np.ones(2))
C2 = np.array([0.3, 0.7])


def quadratic(c, fail_above=None):
    """Return of ``-(x - c)^2`` summed; failure (no return) when ``x[-1] > fail_above``."""

    def rollout(x):
        if fail_above is not None and x[-1] > fail_above:
            return Outcome(False, None)
        return Outcome(True, -float(np.sum((x - c) ** 2)))

    return rollout


def run(opt, rollout, n=None):
    """Ask and tell until the optimizer is done (or ``n`` points); the asked points (k, m)."""
    asked = []
    while not opt.done and (n is None or len(asked) < n):
        x = opt.ask()
        asked.append(x)
        opt.tell(x, rollout(x))
    return np.array(asked)
