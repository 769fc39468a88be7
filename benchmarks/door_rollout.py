"""Speed of the door simulation, and (with --sweep) the success / force map over theta.

    python benchmarks/door_rollout.py            # compile and rollout wall times
    python benchmarks/door_rollout.py --sweep    # 9 x 7 grid over theta = (shift, width)

theta = (grasp shift along the lever relative to the demonstration, m; finger opening width, m).
Each grid point re-solves the demonstration's IK with the grasp moved (``shifted_reference``) and
simulates one 5 s trial. A cell prints the mean interaction force (N) of a success, or a failure
code: ``L`` latch never released (handle not pressed far enough), ``H`` hand lost the handle,
``D`` door not past the threshold, ``IK`` no IK solution.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from corl.tasks.door.demo import DEMO_GRASP_R, scripted_demonstration, shifted_reference
from corl.tasks.door.scene import load_scene
from corl.tasks.door.sim import rollout


def speed(repeats: int = 5) -> None:
    t0 = time.perf_counter()
    load_scene.cache_clear()
    scene = load_scene()
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    demo = scripted_demonstration(scene)
    t_demo = time.perf_counter() - t0
    ref = demo.reference()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = rollout(ref, t_contact=demo.t_contact, scene=scene)
        times.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    shifted_reference(demo, [0.03, 0.014], scene)
    t_shift = time.perf_counter() - t0
    print("| what | wall time (s) |\n|---|---|")
    print(f"| scene compile (first, incl. URDF fuse) | {t_compile:.3f} |")
    print(f"| scripted demonstration (IK) | {t_demo:.3f} |")
    print(f"| shifted_reference (IK) | {t_shift:.3f} |")
    print(f"| 5 s rollout at 500 Hz, median of {repeats} | {np.median(times):.3f} |")
    print(f"\ndemonstration: {result.summary()}")


def sweep(n_shift: int = 9, n_width: int = 7) -> None:
    scene = load_scene()
    demo = scripted_demonstration(scene)
    shifts = np.linspace(-0.02, 0.12, n_shift)
    widths = np.linspace(0.010, 0.028, n_width)
    t0 = time.perf_counter()
    rows = []
    for width in widths:
        cells = []
        for shift in shifts:
            try:
                ref = shifted_reference(demo, [shift, width], scene)
            except Exception:
                cells.append("IK")
                continue
            res = rollout(ref.reference(), t_contact=ref.t_contact, scene=scene)
            if res.success:
                cells.append(f"{res.force_mean:.1f}")
            elif np.isnan(res.t_release):
                cells.append("L")
            elif not res.held:
                cells.append("H")
            else:
                cells.append("D")
        rows.append(cells)
    header = " | ".join(f"{DEMO_GRASP_R + s:.3f}" for s in shifts)
    print(f"grasp r from the pivot (m; demo {DEMO_GRASP_R}) across, width (m) down; "
          "success: mean force N\n")
    print(f"| width \\ r | {header} |")
    print("|---" * (n_shift + 1) + "|")
    for width, cells in zip(widths, rows):
        print(f"| {width:.3f} | " + " | ".join(cells) + " |")
    print(f"\n{n_shift * n_width} rollouts in {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sweep", action="store_true", help="sweep theta on a 9 x 7 grid")
    args = parser.parse_args()
    sweep() if args.sweep else speed()
