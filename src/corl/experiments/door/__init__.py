"""The door study of Sec. VIII-B (Fig. 3, ``corl bench door``), from the lowest module up.

* :mod:`~corl.experiments.door.runs`: one run's record (:class:`DoorRun`), the door task of a
  worker process, and CORL's runs (one round of Algorithm 1);
* :mod:`~corl.experiments.door.dmp`: the DMP+PoWER baseline's runs;
* :mod:`~corl.experiments.door.safe_region`: the ground truth over theta and a failure's distance to it;
* :mod:`~corl.experiments.door.curves`: failures and best return over trials;
* :mod:`~corl.experiments.door.bench`: every method and seed, the safe regions and the table.

Its text tables are in :mod:`corl.experiments.tables`, its figure in :mod:`corl.experiments.figures`.
"""

from corl.experiments.door.bench import DOOR_METHODS, PAPER_FIG3, DoorBench, aggregate, door_sweep, run_one
from corl.experiments.door.curves import run_curves, trial_curves
from corl.experiments.door.dmp import run_dmp_power
from corl.experiments.door.runs import CORL_METHODS, DoorRun, run_corl, true_return
from corl.experiments.door.safe_region import SafeRegion, distance_to_safe, safe_region

__all__ = ["DOOR_METHODS", "CORL_METHODS", "PAPER_FIG3", "DoorRun", "DoorBench", "SafeRegion", "run_corl",
           "run_dmp_power", "run_one", "door_sweep", "aggregate", "safe_region", "distance_to_safe", "true_return",
           "run_curves", "trial_curves"]
