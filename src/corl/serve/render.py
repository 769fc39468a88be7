"""The video process of ``corl serve`` (:class:`corl.serve.dashboard.Video`): loads the task from the
server's command line, then renders one job per line of stdin and answers one line on stdout.

    python -m corl.serve.render TASK_SPEC SEED

A job is ``{"trial": i, "w_demo": [...], "w": [...], "path": "..."}``; the answer ``{"path": "..."}`` or
``{"error": "<one line>"}``. It runs at low priority, apart from the learner's process: rendering
never touches the task object the learner uses, and a crash here costs the dashboard its video only.
"""

from __future__ import annotations

import inspect
import json
import os
import sys


def main(argv: list[str]) -> int:
    import numpy as np

    from corl.tasks.registry import load_task

    try:
        os.nice(10)
    except OSError:
        pass
    task = load_task(argv[0], seed=int(argv[1]))
    for line in sys.stdin:
        try:
            job = json.loads(line)
            args = (np.asarray(job["w_demo"], dtype=float), np.asarray(job["w"], dtype=float), job["path"])
            if "labels" in inspect.signature(task.render_comparison).parameters:  # the door's: name the trial
                path = task.render_comparison(*args, labels=("demonstration", f"trial {job['trial']}"))
            else:
                path = task.render_comparison(*args)
            answer = {"path": str(path)}
        except Exception as exc:  # the dashboard shows it as a note
            answer = {"error": " ".join(f"{type(exc).__name__}: {exc}".split())[:300]}
        print(json.dumps(answer), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
