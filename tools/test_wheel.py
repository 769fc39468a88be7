"""The release as a user gets it (`make test-wheel`, run by CI): the wheel, not the checkout.

    .venv/bin/python tools/test_wheel.py            # build, check, install, run; prints each phase's time

1. ``python -m build`` makes the sdist and the wheel; ``tools/check_dist.py`` checks their files.
2. A fresh venv outside the checkout gets the wheel at the locked versions (``-c constraints.txt``)
   and pytest; ``corl`` must then be imported from that venv, not from ``src/``.
3. From a folder outside the checkout, with no ``MUJOCO_GL`` and no display: ``corl --help``;
   ``corl run door --seed 0 --video`` learns and writes its video; ``corl status`` names the same
   learner's best (trial, return, theta) and best observed reading as summary.json.
4. One test file of the MuJoCo kit (tests/mujoco/test_kinematics.py with its conftest), copied out
   of the checkout, passes against the installed wheel; the example robots resolve.

Exits 1 at the first phase that fails, with what it ran and printed.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HEADLESS = ("MUJOCO_GL", "DISPLAY", "WAYLAND_DISPLAY", "PYTHONPATH", "VIRTUAL_ENV")


def step(title: str, args: list[str], *, cwd: Path, env: dict | None = None, quiet: bool = False,
         timeout: float = 900) -> str:
    """Run ``args``; print the title and the time it took; stop the script when it fails."""
    print(f"==> {title}", flush=True)
    t0 = time.perf_counter()
    out = subprocess.run(args, cwd=cwd, env=env, text=True, capture_output=quiet, timeout=timeout,
                         stdin=subprocess.DEVNULL)
    print(f"    {time.perf_counter() - t0:.1f} s", flush=True)
    if out.returncode != 0:
        print(f"FAILED (exit {out.returncode}): {' '.join(map(str, args))}\n{out.stdout or ''}{out.stderr or ''}")
        sys.exit(1)
    return out.stdout or ""


def check(ok: bool, what: str) -> None:
    if not ok:
        print(f"FAILED: {what}")
        sys.exit(1)


def main() -> int:
    t_all = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix="corl-wheel-"))  # outside the checkout
    dist, venv, run_dir = work / "dist", work / "venv", work / "run"
    run_dir.mkdir()
    step("building the sdist and the wheel (python -m build)", [sys.executable, "-m", "build", "--outdir", str(dist),
                                                                 str(ROOT)], cwd=ROOT, quiet=True)
    print(step("checking their files (tools/check_dist.py)", [sys.executable, str(ROOT / "tools" / "check_dist.py"),
                                                             str(dist)], cwd=ROOT, quiet=True).strip())
    wheel = next(dist.glob("corl_skills-*.whl"))
    step(f"a fresh venv outside the checkout: {venv}", [sys.executable, "-m", "venv", str(venv)], cwd=work)
    py, corl = venv / "bin" / "python", venv / "bin" / "corl"
    step("installing the wheel and pytest at the locked versions (pip install -c constraints.txt)",
         [str(py), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "-c", str(ROOT / "constraints.txt"),
          str(wheel), "pytest"], cwd=work)
    env = {k: v for k, v in os.environ.items() if k not in HEADLESS}
    env["OPENBLAS_NUM_THREADS"] = "1"
    where = step("where corl is imported from, and the versions it runs on",
                 [str(py), "-c", "import corl, corl.versions as v; print(corl.__file__); "
                                 "print(' '.join(f'{k} {x}' for k, x in v.library_versions().items()))"],
                 cwd=run_dir, env=env, quiet=True).splitlines()
    check(where[0].startswith(str(venv)), f"corl imported from {where[0]}, not from the wheel in {venv}")
    print(f"    {where[0]}\n    {where[1]}")
    check("learn a manipulation skill" in step("corl --help", [str(corl), "--help"], cwd=run_dir, env=env, quiet=True),
          "corl --help did not describe corl")
    summary = json.loads(step("corl run door --seed 0 --video (no MUJOCO_GL, no display)",
                              [str(corl), "run", "door", "--seed", "0", "--video", "--out", "door", "--quiet", "--json"],
                              cwd=run_dir, env=env, quiet=True))
    video = run_dir / "door" / Path(summary["files"].get("video", "none")).name
    check(video.is_file() and video.stat().st_size > 10_000, f"no video: {summary['files']}")
    print(f"    {summary['trials']} trials, {summary['failures']} failures, learner's best {summary['best_return']:.4f} "
          f"at trial {summary['best_trial']}; {video.name} {video.stat().st_size // 1024} KiB")
    status = json.loads(step("corl status --json on that run", [str(corl), "status", "--store", "door/run.corl", "--json"],
                             cwd=run_dir, env=env, quiet=True))
    best = status["best"]
    check(best["trial"] == summary["best_trial"] and abs(best["return"] - summary["best_return"]) < 1e-12
          and best["theta"] == summary["best_theta"], f"corl status's best {best} is not summary.json's")
    check(status["best_observed"] == summary["best_observed"],
          f"best observed: status {status['best_observed']} against summary.json {summary['best_observed']}")
    print(f"    corl status and summary.json: the learner's best at trial {best['trial']}, "
          f"return {best['return']:.6g}; best observed {status['best_observed']['return']:.6g}")
    kit = run_dir / "kit"
    kit.mkdir()
    for name in ("conftest.py", "test_kinematics.py"):
        shutil.copy(ROOT / "tests" / "mujoco" / name, kit / name)
    step("a test of the MuJoCo kit against the wheel (tests/mujoco/test_kinematics.py)",
         [str(py), "-m", "pytest", "-q", "-p", "no:cacheprovider", str(kit)], cwd=kit, env=env)
    step("the example robots resolve (example_robot_dir)",
         [str(py), "-c", "from corl.mujoco import example_robot_dir as d; "
                         "[print('   ', d(n)) for n in ('pr2_description', 'panda_description')]"],
         cwd=run_dir, env=env)
    shutil.rmtree(work, ignore_errors=True)
    print(f"test-wheel: all phases passed in {time.perf_counter() - t_all:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
