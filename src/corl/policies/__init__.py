"""Policy representations for black-box baselines: dynamic movement primitives (Sec. VIII-B).

:class:`DMP` is the policy of the DMP + PoWER baseline (Kober & Peters 2011): a per-joint DMP
learned from the demonstration whose shape weights and goals form the learnable parameter vector
(96 numbers for the door's 8 dimensions and 11 basis functions).
"""

from corl.policies.dmp import DEFAULT_DMP_CONFIG, DMP, DMPConfig, basis_functions, forcing_features, phase

__all__ = ["DMP", "DMPConfig", "DEFAULT_DMP_CONFIG", "basis_functions", "forcing_features", "phase"]
