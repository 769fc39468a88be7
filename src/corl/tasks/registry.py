"""Finding a task by name or by import path ``package.module:factory``."""

from __future__ import annotations

import importlib
import inspect
import os
import sys

import numpy as np

from corl.errors import CorlError, InputError
from corl.problem import Task, check_task

__all__ = ["load_task", "check_task_spec", "BUILTIN_TASKS"]

BUILTIN_TASKS = ("synthetic", "synthetic-context", "door")


def load_task(spec: str, *, seed: int = 0) -> Task:
    """Build a task: a built-in name, or ``package.module:factory``.

    The factory is called with ``seed=seed`` when its signature takes a ``seed`` (``corl run --seed``),
    else with no arguments; the task it gives is checked (:func:`corl.problem.check_task`).
    The spec comes from the command line only, never from a store: importing it runs its code.
    Every failure (a malformed spec, an import or a factory that raises) is an :class:`InputError`.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"the seed must be a non-negative integer, got {seed!r}")
    from corl.tasks.synthetic import SyntheticTask

    if spec == "synthetic":
        return SyntheticTask(SyntheticTask.random_start(np.random.default_rng([seed, 2016])))
    if spec == "synthetic-context":
        from corl.tasks.synthetic import ContextualSyntheticTask

        rng = np.random.default_rng([seed, 2016])
        w0 = SyntheticTask.random_start(rng)
        while not -1.0 < np.arctan2(w0[1], w0[0]) < 2.0:  # safe in every context of the box
            w0 = SyntheticTask.random_start(rng)
        return ContextualSyntheticTask(w0)
    if spec == "door":
        from corl.tasks.door.task import DoorTask

        return DoorTask(seed=seed)
    check_task_spec(spec)
    module_name, attr = _split_spec(spec)
    if os.getcwd() not in sys.path:  # like `python -m`: modules next to where the command runs
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise InputError(f"cannot import task module '{module_name}' ({exc}); check the path and PYTHONPATH") from None
    except Exception as exc:  # the module itself raised while being imported
        raise InputError(f"importing task module '{module_name}' raised {type(exc).__name__}: {exc}; "
                         "fix the module") from None
    factory = getattr(module, attr, None)
    if factory is None:
        raise InputError(f"module '{module_name}' has no attribute '{attr}'")
    task = _call_factory(spec, factory, seed) if callable(factory) and not isinstance(factory, Task) else factory
    return check_task(task, f"'{spec}'")


def _call_factory(spec: str, factory, seed: int):
    """``factory(seed=seed)`` when its signature takes ``seed`` (or ``**kwargs``), else ``factory()``."""
    try:
        parameters = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):  # a builtin or C callable: no signature to read
        parameters = ()
    takes_seed = any(p.name == "seed" or p.kind is p.VAR_KEYWORD for p in parameters)
    try:
        return factory(seed=seed) if takes_seed else factory()
    except CorlError:
        raise
    except Exception as exc:
        raise InputError(f"the task factory '{spec}' raised {type(exc).__name__}: {exc}; fix the factory "
                         f"(call it in Python to see the traceback)") from None


def _split_spec(spec: str) -> tuple[str, str]:
    """``package.module:factory`` as (module, factory), or :class:`InputError` for anything else."""
    module_name, _, attr = spec.partition(":")
    parts = module_name.split(".")
    if not (all(p.isidentifier() for p in parts) and attr.isidentifier()):
        raise InputError(f"task '{spec}' is not an import path 'package.module:make_task' (dotted names, one "
                         f"colon, no relative or empty parts); or use one of {', '.join(BUILTIN_TASKS)}")
    return module_name, attr


def check_task_spec(spec: str) -> str:
    """``spec`` if it names a task in a valid form (without importing anything), else :class:`InputError`."""
    if spec in BUILTIN_TASKS:
        return spec
    if ":" not in spec:
        raise InputError(f"unknown task '{spec}'; use one of {', '.join(BUILTIN_TASKS)} "
                         "or an import path 'package.module:make_task'")
    _split_spec(spec)
    return spec
