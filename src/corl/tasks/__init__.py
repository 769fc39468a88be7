"""Tasks a learner can be run on: the synthetic benchmark of Sec. VIII-A, the simulated PR2 door of
Sec. VIII-B (MuJoCo, imported lazily) and the registry that finds a task by name or import path.
"""
