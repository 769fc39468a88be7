"""The drawing processes of ``corl serve`` (:mod:`corl.serve.dashboard`), apart from the learner's.

    python -m corl.serve.render --figures          # the dashboard's figures (Figures)
    python -m corl.serve.render TASK_SPEC SEED     # the video of the last told trial (Video)

The figures process reads pickled snapshots of the run (8-byte length, then the pickle) from the
server that started it, draws them with :mod:`corl.experiments.figures` and answers one JSON line.
The video process loads the task from the server's command line, then renders one job per line of
stdin and answers one line on stdout.

A job is ``{"trial": i, "w_demo": [...], "w": [...], "path": "..."}``; the answer ``{"path": "..."}`` or
``{"error": "<one line>"}``. It runs at low priority, apart from the learner's process: rendering
never touches the task object the learner uses, and a crash here costs the dashboard its video only.
"""

from __future__ import annotations

import inspect
import json
import os
import sys


def draw_figures(records, J, data, labels, folder: str) -> dict:
    """The dashboard's figures into ``folder``: ``{"files": {name: path}, "notes": {name: why not}}``."""
    from pathlib import Path

    from corl.experiments.figures import ReturnMapData, plot_return_map, plot_trials

    files, notes, note = {}, {}, None
    if not isinstance(data, ReturnMapData):
        data, note = None, data
    elif data.bounds.dim > 2:
        data, note = None, f"No return map: theta has {data.bounds.dim} dimensions, a map shows 1 or 2."
    if any(r.outcome is not None for r in records):
        files["trials"] = str(plot_trials(records, J, Path(folder) / "trials.png"))
    else:
        notes["trials"] = "No trial told yet."
    if data is not None:
        try:
            files["return_map"] = str(plot_return_map(data, Path(folder) / "return_map.png", labels=labels))
        except ValueError as exc:
            note = f"No return map: {exc}."
    if note is not None:
        notes["return_map"] = note
    return {"files": files, "notes": notes}


def figures_loop() -> int:
    """Jobs are pickles (8-byte length first) from the server's own process, the only writer of this pipe."""
    import pickle

    source = sys.stdin.buffer
    while True:
        head = source.read(8)
        if len(head) < 8:
            return 0
        job = pickle.loads(source.read(int.from_bytes(head, "little")))
        try:
            answer = draw_figures(**job)
        except Exception as exc:  # a note on the page
            answer = {"files": {}, "notes": {"trials": f"the figures could not be drawn ({type(exc).__name__}: "
                                                       f"{' '.join(str(exc).split())[:200]})"}}
        print(json.dumps(answer), flush=True)


def main(argv: list[str]) -> int:
    import numpy as np

    from corl.mujoco.video import RENDERING_HINT
    from corl.tasks.registry import load_task

    try:
        os.nice(10)
    except OSError:
        pass
    if argv[:1] == ["--figures"]:
        return figures_loop()
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
            text = " ".join(f"{type(exc).__name__}: {exc}".split())[:300]
            if "GL" in text:
                text += f". {RENDERING_HINT} before corl serve"
            answer = {"error": text}
        print(json.dumps(answer), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
