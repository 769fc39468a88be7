"""The settings of Algorithm 1 (:class:`CORLConfig`), apart from the learner that reads them.

``min_J_decrease`` is beyond the paper (whose step 1 and phase steps end only when w moves less than
``eps_w``): on a robot every step is a trial, and a step that buys almost no smoothness can still
change the return; at 0 (the default) the paper's rule alone holds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from corl import checks
from corl.errors import InputError
from corl.optimizers.base import START_RETRIES
from corl.trajectory.solver import SolverConfig

__all__ = ["CORLConfig"]


@checks.keywords({"rl_budget": "CORL's budget is CORLConfig(max_rl_trials=N) (black-box trials over the whole run)"})
@dataclass(frozen=True)
class CORLConfig:
    """Settings of Algorithm 1 (paper defaults for the synthetic benchmark)."""

    eps_max: float = 1e-3
    eps_w: float = 1e-5
    eps_theta: float = 3e-3
    theta_step_stop: bool = False
    max_rounds: int = 10
    max_optimization_steps: int = 5000
    max_rl_trials: int = 100  # black-box trials of step 2 over the whole run, all rounds (see CORL)
    rollout_every_step: bool = True
    reuse_data: bool = True
    max_phase_steps: int = 0  # phase steps (Eq. 10) after the trajectory steps; needs task.spline
    min_J_decrease: float = 0.0  # a step-1 or phase step that lowers J by less than this fraction ends the chain
    start_retries: int = START_RETRIES  # a failed demonstration is rolled out again this often before it is refused
    solver: SolverConfig = field(default_factory=SolverConfig)
    demo_tolerance: float = 1e-3  # the demonstration needs max|h(w0, theta0)| <= this, in h's units

    def __post_init__(self) -> None:  # every field checked here, before any rollout (corl.checks)
        for name in ("eps_max", "eps_w", "eps_theta", "demo_tolerance"):
            object.__setattr__(self, name, checks.number(f"CORLConfig.{name}", getattr(self, name), low=0.0, low_open=True))
        object.__setattr__(self, "start_retries", checks.integer("CORLConfig.start_retries", self.start_retries))
        for name in ("max_rounds", "max_optimization_steps", "max_rl_trials"):
            object.__setattr__(self, name, checks.integer(f"CORLConfig.{name}", getattr(self, name), low=1))
        object.__setattr__(self, "max_phase_steps", checks.integer("CORLConfig.max_phase_steps", self.max_phase_steps))
        object.__setattr__(self, "min_J_decrease", checks.number("CORLConfig.min_J_decrease", self.min_J_decrease,
                                                                 low=0.0, high=1.0, high_open=True))
        for name in ("theta_step_stop", "rollout_every_step", "reuse_data"):
            checks.flag(f"CORLConfig.{name}", getattr(self, name))
        if not isinstance(self.solver, SolverConfig):
            raise InputError(f"CORLConfig.solver must be a corl.settings.SolverConfig, got {type(self.solver).__name__}")
