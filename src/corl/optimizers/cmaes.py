"""CMA-ES baseline (Sec. VIII-A, "CMA") over a box, one trial at a time, on top of pycma.

pycma works on a whole population: ``es.ask()`` returns ``lambda`` points and ``es.tell`` needs all
their values at once. :class:`CMAES` hands the population out point by point through the common
``ask`` / ``tell`` protocol and updates the distribution when the last member has been told.

Glossary
--------
u        : a point of the unit box ``[0, 1]^m``; pycma searches in ``u``, ``x = lower + u * width``
sigma0   : initial step size, a fraction of the box width (the same in every coordinate)
lambda   : population size (pycma's ``popsize``)
score    : the scalar maximised, ``R`` on success and ``failure_return`` on failure; pycma minimises
           ``-score``, the paper's ``o(w) = (J - R)[S] + 15[not S]`` when ``R`` includes ``-J``

Decisions
---------
* Bounds are pycma's own ``BoundTransform`` on the unit box, so ``sigma0`` and ``tolx`` are
  fractions of the box width and every proposal lies inside the box.
* Randomness comes from a :class:`numpy.random.Generator` passed to pycma as its ``randn`` option.
  pycma's ``seed`` option would reseed numpy's *global* generator, so any other code drawing from
  ``np.random`` between two populations (or a second optimizer in the same process) would change
  the sequence; with ``randn`` the sequence depends on ``seed`` alone.
* pycma 4.4.4 raises in 1-D when a standard deviation crosses its default cap ``maxstd`` (a third
  of the box range): the per-coordinate rescaling it then applies needs ``m >= 2``. In 1-D the cap
  is therefore switched off in pycma and applied here to the step size after each update.
* A population that fails entirely has a flat fitness (every member scores ``failure_return``).
  pycma's function-value stopping rules would end the search there; they are off unless
  ``CMAESConfig.flat_fitness_stops`` is set, and ``tolx`` and pycma's other rules remain.
* A point told without having been asked (a demonstration, a point from another method) cannot
  enter the CMA update, which needs the population it sampled. It is kept in the data
  (``X_``, ``best``) only. The population member that is out stays pending.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from corl.errors import InputError
from corl.optimizers.base import BlackBoxOptimizer, StopReason, as_point, as_rng, score_of
from corl.problem import Bounds, Outcome

__all__ = ["CMAES", "CMAESConfig"]

_MAXSTD_FRACTION = 1.0 / 3.0  # pycma's default maxstd_boundrange, re-applied by hand in 1-D


@dataclass(frozen=True)
class CMAESConfig:
    """Settings of :class:`CMAES`.

    Attributes
    ----------
    sigma0 : initial step size as a fraction of the box width, in (0, 1].
    popsize : population size ``lambda``; None takes pycma's default ``4 + floor(3 ln m)``.
    tolx : pycma's stopping tolerance on the step size and the evolution path, as a fraction of
        the box width.
    flat_fitness_stops : keep pycma's stopping rules on function values (``tolfun``,
        ``tolfunhist``, ``tolflatfitness``). Off by default: a population that fails entirely
        scores the constant ``failure_return`` everywhere, and these rules read that plateau as
        convergence and stop after one or two generations, with the budget unspent.
    """

    sigma0: float = 0.3
    popsize: int | None = None
    tolx: float = 1e-8
    flat_fitness_stops: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma0) and 0.0 < self.sigma0 <= 1.0):
            raise InputError(f"sigma0 is a fraction of the box width and must lie in (0, 1], got {self.sigma0}")
        if self.popsize is not None:
            if isinstance(self.popsize, bool) or int(self.popsize) != self.popsize or self.popsize < 2:
                raise InputError(f"popsize must be an integer >= 2 or None (pycma's default), got {self.popsize!r}")
            object.__setattr__(self, "popsize", int(self.popsize))
        if not (np.isfinite(self.tolx) and self.tolx > 0.0):
            raise InputError(f"tolx must be a positive fraction of the box width, got {self.tolx}")
        if not isinstance(self.flat_fitness_stops, (bool, np.bool_)):
            raise InputError(f"flat_fitness_stops must be True or False, got {self.flat_fitness_stops!r}")
        object.__setattr__(self, "flat_fitness_stops", bool(self.flat_fitness_stops))


class _GaussianSource:
    """pycma's ``randn(lam, N)`` drawn from one Generator (a class, not a lambda, so it pickles)."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng

    def __call__(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)


class CMAES(BlackBoxOptimizer):
    """CMA-ES (pycma) maximising ``score_of(outcome, failure_return)`` over a box.

    Parameters
    ----------
    bounds : search box, (m,) each; m = 1 works.
    x0 : (m,) initial mean, inside ``bounds`` (e.g. the demonstration).
    config : step size, population size and ``tolx``.
    failure_return : score of a failed trial (the paper's constant cost 15 -> -15.0).
    max_evals : trial budget; :attr:`done` turns True when it is spent.
    seed : int, Generator or None; the same seed gives the same sequence of points.

    Attributes
    ----------
    es_ : the ``cma.CMAEvolutionStrategy`` searching the unit box.
    mean_ : (m,) current distribution mean, in box coordinates.

    Notes
    -----
    :attr:`done` is also True, with ``stop_reason`` ``CONVERGED``, when pycma's stopping rules
    (``es_.stop()``: tolx, flat fitness, stagnation, ...) fire at the end of a population; a
    ``while not opt.done`` loop never sees a :class:`~corl.errors.StateError`. With ``start``
    given, the first trial is ``start`` itself (kept in the data only, like any point CMA-ES did
    not sample); ``x0`` is the mean of the first population.
    """

    def __init__(self, bounds: Bounds, x0, config: CMAESConfig = CMAESConfig(), *,
                 failure_return: float = -15.0, max_evals: int = 100, seed=None, start=None) -> None:
        import cma  # heavy import kept out of ``import corl``

        super().__init__(bounds, max_evals=max_evals, name="CMA-ES", start=start)
        if not np.isfinite(failure_return):
            raise InputError(f"failure_return must be finite, got {failure_return}")
        x0 = as_point(x0, bounds, name=self.name, what="x0")
        self.config = config
        self.failure_return = float(failure_return)
        self.rng = as_rng(seed)
        options = {
            "bounds": [0.0, 1.0],
            "randn": _GaussianSource(self.rng),
            "seed": np.nan,  # NaN: pycma leaves numpy's global generator alone
            "tolx": config.tolx,
            "verbose": -9,
        }
        if config.popsize is not None:
            options["popsize"] = config.popsize
        if not config.flat_fitness_stops:  # see CMAESConfig.flat_fitness_stops
            options.update(tolfun=0.0, tolfunhist=0.0, tolflatfitness=np.inf)
        if bounds.dim == 1:
            options["maxstd"] = np.inf  # see the module docstring; capped in _cap_step_size
        self.es_ = cma.CMAEvolutionStrategy(bounds.to_unit(x0), config.sigma0, options)
        self._population: list[np.ndarray] = []  # the u's of the current population, as pycma gave them
        self._points: list[np.ndarray] = []  # the same in box coordinates, as handed out
        self._scores: list[float | None] = []  # score of each member, None until told
        self._next = 0  # index of the next member to hand out

    @property
    def mean_(self) -> np.ndarray:
        """(m,) distribution mean in box coordinates."""
        return self.bounds.clip(self.bounds.from_unit(self.es_.result.xfavorite))

    # -- BlackBoxOptimizer hooks ---------------------------------------------------------------
    def _propose(self) -> np.ndarray | StopReason:
        if self._between_populations():
            if self.es_.stop():
                return StopReason.CONVERGED
            self._new_population()
        # the base class decides again only after the member handed out last was told (or
        # withdrawn), and the generation is updated as soon as the last member is told: a member
        # is always left
        x = self._points[self._next]
        self._next += 1
        return x

    def _withdraw(self, x: np.ndarray) -> None:
        """A member decided but not handed out goes back: it is handed out again next time."""
        if self._next > 0 and self._scores[self._next - 1] is None and np.array_equal(x, self._points[self._next - 1]):
            self._next -= 1

    def _observe(self, x: np.ndarray, outcome: Outcome) -> None:
        k = self._member_of(x)
        if k is None:
            return  # not asked: kept in X_ only (module docstring)
        self._scores[k] = score_of(outcome, self.failure_return)
        if all(s is not None for s in self._scores):
            self._update()

    # -- population bookkeeping ----------------------------------------------------------------
    def _between_populations(self) -> bool:
        return not self._population

    def _new_population(self) -> None:
        self._population = [np.asarray(u, dtype=float) for u in self.es_.ask()]
        self._points = [self.bounds.clip(self.bounds.from_unit(u)) for u in self._population]
        self._scores = [None] * len(self._population)
        self._next = 0

    def _member_of(self, x: np.ndarray) -> int | None:
        """Index of the handed-out, not yet told member that ``x`` answers (base class tolerance), or None."""
        for k in range(self._next):
            if self._scores[k] is None and self._answers(x, self._points[k]):
                return k
        return None

    def _update(self) -> None:
        """One CMA-ES generation: pycma minimises, so it is told ``-score``."""
        self.es_.tell(self._population, [-s for s in self._scores])
        self._cap_step_size()
        self._population, self._points, self._scores, self._next = [], [], [], 0

    def _cap_step_size(self) -> None:
        """1-D only: keep the standard deviation below a third of the box (pycma's default cap)."""
        if self.bounds.dim != 1:
            return
        std = float(self.es_.stds[0])
        if std > _MAXSTD_FRACTION:
            self.es_.sigma *= _MAXSTD_FRACTION / std
