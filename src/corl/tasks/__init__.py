"""Tasks a learner can be run on: the synthetic benchmark of Sec. VIII-A, the simulated PR2 door of
Sec. VIII-B (MuJoCo, imported lazily) and the registry that finds a task by name or import path.
:class:`corl.tasks.NoisyTask` (:mod:`corl.tasks.noisy`) shows any of them through a noisy return
sensor and a flaky success sensor, as a real robot's would be (``corl run --return-noise --flip``).
"""


def __getattr__(name: str):
    if name == "NoisyTask":  # on first use: `import corl.tasks` stays free of numpy
        from corl.tasks.noisy import NoisyTask

        return NoisyTask
    raise AttributeError(f"module 'corl.tasks' has no attribute '{name}'")
