"""Finding a task by name or by import path ``package.module:factory``."""

from __future__ import annotations

import importlib
import os
import sys

import numpy as np

from corl.errors import InputError
from corl.problem import Task

__all__ = ["load_task", "BUILTIN_TASKS"]

BUILTIN_TASKS = ("synthetic", "door")


def load_task(spec: str, *, seed: int = 0) -> Task:
    """Build a task: a built-in name, or ``package.module:factory`` (called with no arguments)."""
    if spec == "synthetic":
        from corl.tasks.synthetic import SyntheticTask

        return SyntheticTask(SyntheticTask.random_start(np.random.default_rng([seed, 2016])))
    if spec == "door":
        from corl.tasks.door.task import DoorTask

        return DoorTask(seed=seed)
    if ":" not in spec:
        raise InputError(f"unknown task '{spec}'; use one of {', '.join(BUILTIN_TASKS)} "
                         "or an import path 'package.module:make_task'")
    module_name, _, attr = spec.partition(":")
    if os.getcwd() not in sys.path:  # like `python -m`: modules next to where the command runs
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"cannot import task module '{module_name}' ({exc}); check the path and PYTHONPATH") from None
    factory = getattr(module, attr, None)
    if factory is None:
        raise InputError(f"module '{module_name}' has no attribute '{attr}'")
    task = factory() if callable(factory) and not isinstance(factory, Task) else factory
    missing = [a for a in ("name", "theta_bounds", "w_bounds", "demonstration", "cost_residuals",
                           "projection", "theta_of", "rollout") if not hasattr(task, a)]
    if missing:
        raise InputError(f"'{spec}' did not give a task: it lacks {', '.join(missing)} (see corl.problem.Task)")
    return task
