"""Exception types of corl.

Every error corl raises on purpose derives from :class:`CorlError`, and its message says what was
wrong and what to do about it.
"""

from __future__ import annotations


class CorlError(Exception):
    """Base class of every error corl raises on purpose."""


class InputError(CorlError, ValueError):
    """An argument has the wrong shape, type or value (theta out of bounds, NaN return, ...)."""


class NumericalError(CorlError, ArithmeticError):
    """A numerical routine failed (a matrix that stays indefinite after jitter, ...)."""


class DemonstrationFailedError(CorlError):
    """The demonstration given to CORL did not succeed, so Algorithm 1 has no safe start."""


class RolloutError(CorlError):
    """A rollout raised; the trial stays pending and can be answered again."""


class StateError(CorlError, RuntimeError):
    """A call that does not fit the learner's or optimizer's state (tell without ask, ...)."""


class MissingExtraError(CorlError, ImportError):
    """An optional package corl needs for this feature is not installed (``pip install 'corl-skills[extra]'``)."""


class TaskError(CorlError):
    """The task's own code raised inside the learner (its ``cost_residuals``, ``constraint``, ...).

    ``member`` names the task's member that raised, ``trial`` the trial the learner was taking in
    (or working out), ``detail`` the original error on one line.
    """

    def __init__(self, message: str, *, member: str, trial: int, detail: str) -> None:
        super().__init__(message)
        self.member, self.trial, self.detail = member, trial, detail
