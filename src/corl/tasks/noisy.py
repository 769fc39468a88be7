"""A task seen through a noisy return sensor and a flaky success sensor, as on a real robot.

:class:`NoisyTask` wraps any task (:class:`corl.problem.Task`) and is one itself: every member is
the wrapped task's, except ``rollout(w)``, which reports what imperfect sensors would.

Glossary
--------
R, S         : the return and the success the wrapped task's rollout computed (the truth)
sigma_R      : ``return_noise``, std of the Gaussian error added to every reported return, in R's units
q            : ``flip``, the probability that the reported success is the opposite of S
u, z         : the two draws of one rollout, ``u ~ U[0, 1)`` (flip when ``u < q``), ``z ~ N(0, 1)``

What one rollout reports
------------------------
* ``S = 1``, not flipped: success, return ``R + sigma_R z``;
* ``S = 1``, flipped: failure without a return (a failure observes none);
* ``S = 0``, flipped: success with return ``R + sigma_R z`` when the task's Outcome gave an ``R``
  with its failure; a failure without a return cannot pass for a success, so it is never flipped
  (the built-in tasks give none: on them only successes flip, to false failures);
* ``S = 0``, not flipped: failure, with ``R + sigma_R z`` when the task gave an ``R``, else none.

The demonstration is never flipped: Algorithm 1 starts from a demonstration a person saw succeed
(its return is noisy like any other). The truth goes into the outcome's ``info``:
``true_success``, ``true_return`` and ``flipped``.

Reproducible and resumable: ``(u, z)`` come from a generator seeded by ``(seed, a hash of w's
bytes, k)``, ``k`` the number of earlier rollouts of the same ``w`` (the k-th repeat of a trial,
e.g. a confirmation of the best, reads afresh). Nothing else is kept, so a run gives the same
readings every time, in a forked rollout worker (:mod:`corl.tasks.worker`) as in one process, and a
run resumed from its store (which replays told outcomes and never repeats a rollout) continues with
the readings it would have had: :meth:`corl.session.StoredRun.run` sets the counts from the run's
trials (:meth:`NoisyTask.recount`) before its first rollout.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from dataclasses import dataclass
from typing import Iterable

import numpy as np

from corl.checks import integer, number
from corl.errors import InputError
from corl.problem import Outcome, check_task

__all__ = ["NoisyTask", "SensorNoise", "check_return_noise", "check_flip"]

_STREAM = 0x6E6F6973  # "nois": keeps these draws apart from any other generator seeded by (seed, w)
_OWN = frozenset({"wrapped", "noise", "_demo_w", "_counts"})  # the wrapper's own attributes, never forwarded


def check_return_noise(value, name: str = "return_noise") -> float:
    """``value`` as a std >= 0 (finite), or one :class:`InputError` naming ``name``."""
    try:
        return number(name, value, low=0.0)
    except InputError:
        raise InputError(f"{name} must be a finite standard deviation >= 0 in the return's units (0 for an exact "
                         f"return sensor), got {value!r}") from None


def check_flip(value, name: str = "flip") -> float:
    """``value`` as a probability in [0, 0.5), or one :class:`InputError` naming ``name``."""
    try:
        q = number(name, value, low=0.0, high=0.5)
    except InputError:
        q = 0.5
    if q >= 0.5:
        raise InputError(f"{name} must be a probability in [0, 0.5) that a success label is reported flipped (0 for an "
                         "exact success sensor; from 0.5 on the label says nothing, or the opposite), "
                         f"got {value!r}")
    return q


@dataclass(frozen=True)
class SensorNoise:
    """The sensors of :class:`NoisyTask`: return noise ``return_noise`` (std, in R's units), flip
    probability ``flip`` in [0, 0.5), and ``seed`` (an integer >= 0) of the readings."""

    return_noise: float = 0.0
    flip: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "return_noise", check_return_noise(self.return_noise))
        object.__setattr__(self, "flip", check_flip(self.flip))
        try:
            seed = integer("seed", self.seed, low=0)
        except InputError:
            raise InputError(f"seed must be an integer >= 0 (it seeds the sensor readings), "
                             f"got {self.seed!r}") from None
        object.__setattr__(self, "seed", seed)

    def as_dict(self) -> dict:
        """``{"return_noise", "flip", "seed"}``: what ``summary.json`` and the run store record."""
        return {"return_noise": self.return_noise, "flip": self.flip, "seed": self.seed}

    def draws(self, w: np.ndarray, k: int = 0) -> tuple[float, float]:
        """``(u, z)`` of the rollout of ``w`` (n,) after ``k`` earlier ones of the same ``w``:
        ``u ~ U[0, 1)``, ``z ~ N(0, 1)``, a function of ``(seed, w, k)`` alone."""
        digest = _digest(w)
        key = [self.seed, int.from_bytes(digest[:4], "little"), int.from_bytes(digest[4:], "little"), _STREAM]
        rng = np.random.default_rng(key + [k] if k else key)
        return float(rng.random()), float(rng.standard_normal())


def _digest(w) -> bytes:
    """8 bytes that name ``w`` (n,): a hash of its float64 bytes."""
    return hashlib.blake2b(np.ascontiguousarray(w, dtype=float).tobytes(), digest_size=8).digest()


class NoisyTask:
    """``task`` with a noisy return sensor and a flaky success sensor (see the module docstring).

    Parameters
    ----------
    task : any corl task; checked (:func:`corl.problem.check_task`).
    return_noise : std of the error of a reported return, in the return's units (>= 0).
    flip : probability in [0, 0.5) that the reported success is the opposite of the truth.
    seed : seeds the readings (an integer >= 0); ``corl run`` passes the run's ``--seed``.

    Attributes
    ----------
    wrapped : the task. noise : its :class:`SensorNoise`.

    Every other member is the wrapped task's, optional ones included (corl reads them with
    ``getattr``), so a simulator that rolls out in a worker still does, with the noise applied there;
    ``retimed(time_map)`` and ``with_context(c)`` return the new task wrapped in the same sensors.
    """

    def __init__(self, task, *, return_noise: float = 0.0, flip: float = 0.0, seed: int = 0) -> None:
        self.noise = SensorNoise(return_noise, flip, seed)
        self.wrapped = check_task(task, "the task NoisyTask wraps")
        self._demo_w: np.ndarray | None = None
        self._counts: Counter = Counter()  # rollouts per w (its digest) in this process: k of draws()

    def __getattr__(self, name: str):
        if name.startswith("__") or name in _OWN:  # not set yet (unpickling, copying): not the task's
            raise AttributeError(name)
        value = getattr(self.wrapped, name)
        if name in ("retimed", "with_context") and callable(value):
            def wrapped_too(*args, _make=value, **kwargs):
                return self._same_sensors(_make(*args, **kwargs))

            return wrapped_too
        return value

    def __dir__(self):
        return sorted(set(super().__dir__()) | set(dir(self.wrapped)))

    def __repr__(self) -> str:
        n = self.noise
        return f"NoisyTask({self.wrapped!r}, return_noise={n.return_noise!r}, flip={n.flip!r}, seed={n.seed!r})"

    def _same_sensors(self, task) -> "NoisyTask":
        n = self.noise
        return NoisyTask(task, return_noise=n.return_noise, flip=n.flip, seed=n.seed)

    def _is_demonstration(self, w: np.ndarray) -> bool:
        if self._demo_w is None:
            self._demo_w = np.asarray(self.wrapped.demonstration().w, dtype=float)
        return bool(np.array_equal(np.asarray(w, dtype=float), self._demo_w))

    def recount(self, ws: Iterable[np.ndarray]) -> None:
        """Forget the rollouts counted so far; count ``ws`` (each (n,)) instead: the trials a run has
        told, so that a ``w`` tried before reads its next values (:meth:`corl.session.StoredRun.run`)."""
        self._counts = Counter(_digest(w) for w in ws)

    def rollout(self, w: np.ndarray) -> Outcome:
        """The wrapped rollout of ``w`` (n,) as the sensors report it; the truth in ``info``."""
        outcome = self.wrapped.rollout(w)
        if not isinstance(outcome, Outcome):
            raise InputError(f"task '{self.wrapped.name}': rollout(w) returned {type(outcome).__name__}; it must "
                             "return corl.problem.Outcome(success, return_, info)")
        info = dict(outcome.info)
        truth = bool(info.setdefault("true_success", outcome.success))  # a wrapped NoisyTask's truth stays
        info.setdefault("true_return", outcome.return_)
        key = _digest(w)
        u, z = self.noise.draws(w, self._counts[key])
        self._counts[key] += 1
        success = outcome.success
        if u < self.noise.flip and (success or outcome.return_ is not None) and not self._is_demonstration(w):
            success = not success
        return_ = None
        if outcome.return_ is not None and (success or not outcome.success):  # a success flipped reports none
            return_ = outcome.return_ + self.noise.return_noise * z
        info["flipped"] = success != truth
        return Outcome(success, return_, info)
