"""Families for the bench's tests (loaded by spec, e.g. ``bench_fixtures:low_truth``)."""

from __future__ import annotations

from corl.tasks.synthetic import ContextualSyntheticTask


class LowTruth(ContextualSyntheticTask):
    """A ground truth below what the learners reach (a coarse grid would give one)."""

    name = "synthetic-low-truth"

    def with_context(self, c):
        return LowTruth(self.w0, critical_distance=self.critical_distance, context=c)

    def best_return(self) -> float:
        return 0.5


class NoDemoAbove(ContextualSyntheticTask):
    """A family whose scenes with c > 0.3 have no demonstration (the user's recording stops there)."""

    name = "synthetic-no-demo"

    def with_context(self, c):
        return NoDemoAbove(self.w0, critical_distance=self.critical_distance, context=c)

    def demonstration(self):
        if float(self.context[0]) > 0.3:
            raise RuntimeError(f"no recording for c = {float(self.context[0]):.3f}")
        return super().demonstration()


def low_truth(seed: int = 0):
    return LowTruth()


def no_demo_above(seed: int = 0):
    return NoDemoAbove()


class NoTruthAbove(ContextualSyntheticTask):
    """A family whose best_return() raises for c > 0.3 (its author's search found no success there)."""

    name = "synthetic-no-truth"

    def with_context(self, c):
        return NoTruthAbove(self.w0, critical_distance=self.critical_distance, context=c)

    def best_return(self) -> float:
        if float(self.context[0]) > 0.3:
            raise ValueError(f"no theta of the grid succeeds in scene {float(self.context[0]):.3f}")
        return 1.0


def no_truth_above(seed: int = 0):
    return NoTruthAbove()
