"""Check what `python -m build` made: the wheel and the sdist hold corl and nothing of the checkout's rest.

    python tools/check_dist.py dist/          # the newest corl_skills wheel and sdist in dist/

The wheel must hold every module and data file of ``src/corl`` (the door's scene code, the MuJoCo
kit, the dashboard's static files), the console script ``corl`` and the metadata of the
distribution ``corl-skills`` at ``corl.__version__``; no tests, benchmarks, docs or examples, no
bytecode. The sdist holds the same package plus the README, the licence, the changelog, the lock
and the examples, and no tests. Prints one line per problem and exits 1, or one ``ok`` line.
Standard library only: CI runs it with any Python.
"""

from __future__ import annotations

import re
import sys
import tarfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DIST = "corl_skills"
#: Files the release cannot work without, named here so that a packaging rule that drops them fails.
REQUIRED = ("corl/__init__.py", "corl/_version.py", "corl/offscreen.py", "corl/cli/__init__.py",
            "corl/tasks/door/__init__.py", "corl/tasks/door/scene.py", "corl/mujoco/robot.py",
            "corl/serve/static/dashboard.html", "corl/serve/static/dashboard.js", "corl/serve/static/dashboard.css")
FORBIDDEN = re.compile(r"(^|/)(tests?|benchmarks|docs|examples|tools|\.ci)/|\.py[cod]$|__pycache__|egg-info")


def version() -> str:
    text = (ROOT / "src" / "corl" / "_version.py").read_text()
    return re.search(r'__version__ = "([^"]+)"', text).group(1)


def package_files() -> set[str]:
    """The files of src/corl a release must carry, as ``corl/...`` paths."""
    src = ROOT / "src"
    return {p.relative_to(src).as_posix() for p in (src / "corl").rglob("*")
            if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo")}


def check_wheel(names: list[str], metadata: str, entry_points: str, expected: set[str], release: str) -> list[str]:
    """Problems with a wheel's file list, its METADATA and entry_points.txt (empty: none)."""
    problems = [f"wheel: {n} should not ship" for n in names if FORBIDDEN.search(n)]
    got = {n for n in names if n.startswith("corl/")}
    problems += [f"wheel: {n} missing" for n in sorted((expected | set(REQUIRED)) - got)]
    problems += [f"wheel: {n} is not in src/corl" for n in sorted(got - expected)]
    problems += [f"wheel: {n} outside corl/ and its dist-info" for n in names
                 if not n.startswith(("corl/", f"{DIST}-{release}.dist-info/"))]
    if not re.search(r"^Name: corl-skills$", metadata, re.M):
        problems.append("wheel: METADATA does not name the distribution corl-skills")
    if not re.search(rf"^Version: {re.escape(release)}$", metadata, re.M):
        problems.append(f"wheel: METADATA's version is not corl.__version__ {release}")
    if not re.search(r"^corl = corl\.cli:main$", entry_points, re.M):
        problems.append("wheel: no console script corl = corl.cli:main")
    return problems


def check_sdist(names: list[str], expected: set[str], release: str) -> list[str]:
    """Problems with an sdist's file list (paths inside its top folder)."""
    top = f"{DIST}-{release}/"
    inner = {n[len(top):] for n in names if n.startswith(top)}
    problems = [f"sdist: {n} outside {top}" for n in names if not (n.startswith(top) or n + "/" == top)]
    problems += [f"sdist: {n} should not ship" for n in sorted(inner)
                 if re.search(r"(^|/)(tests?|benchmarks|docs)/|\.py[cod]$|__pycache__", n)]
    needed = {f"src/{n}" for n in expected} | {"pyproject.toml", "README.md", "LICENSE", "CHANGELOG.md",
                                               "constraints.txt", "MANIFEST.in", "examples/planar_button.py"}
    problems += [f"sdist: {n} missing" for n in sorted(needed - inner)]
    return problems


def main(argv: list[str]) -> int:
    folder = Path(argv[0]) if argv else ROOT / "dist"
    release = version()
    wheel, sdist = folder / f"{DIST}-{release}-py3-none-any.whl", folder / f"{DIST}-{release}.tar.gz"
    problems = [f"{p} not found (python -m build --outdir {folder})" for p in (wheel, sdist) if not p.is_file()]
    if problems:
        print("\n".join(problems))
        return 1
    expected = package_files()
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        info = f"{DIST}-{release}.dist-info/"
        problems += check_wheel(names, z.read(info + "METADATA").decode(), z.read(info + "entry_points.txt").decode(),
                                expected, release)
    with tarfile.open(sdist) as t:
        problems += check_sdist(t.getnames(), expected, release)
    if problems:
        print("\n".join(problems))
        return 1
    print(f"ok: {wheel.name} ({len(names)} files: all {len(expected)} of src/corl, no tests) and {sdist.name}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
