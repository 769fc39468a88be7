"""Acquisition functions (PI, UCB, PIBU) and their maximiser."""

from corl.acquisition.maximize import MaximizerConfig, maximize
from corl.acquisition.pi import probability_of_improvement, upper_confidence_bound
from corl.acquisition.pibu import PIBU, PIBUConfig, PIBUVariant

__all__ = ["MaximizerConfig", "maximize", "probability_of_improvement", "upper_confidence_bound",
           "PIBU", "PIBUConfig", "PIBUVariant"]
