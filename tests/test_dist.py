"""tools/check_dist.py, the check of what `python -m build` makes (`make test-wheel` runs it on the real
wheel and sdist): it passes a good file list and names each kind of bad one."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("check_dist", ROOT / "tools" / "check_dist.py")
check_dist = importlib.util.module_from_spec(spec)
spec.loader.exec_module(check_dist)

RELEASE = check_dist.version()
INFO = f"corl_skills-{RELEASE}.dist-info/"
METADATA = f"Metadata-Version: 2.4\nName: corl-skills\nVersion: {RELEASE}\n"
ENTRY = "[console_scripts]\ncorl = corl.cli:main\n"


def _wheel(names):
    expected = check_dist.package_files()
    return check_dist.check_wheel(names, METADATA, ENTRY, expected, RELEASE)


def test_the_version_is_corl_s():
    import corl

    assert RELEASE == corl.__version__


def test_a_wheel_of_the_package_and_its_metadata_passes():
    good = sorted(check_dist.package_files()) + [INFO + "METADATA", INFO + "RECORD", INFO + "entry_points.txt"]
    assert "corl/tasks/door/scene.py" in good and "corl/serve/static/dashboard.js" in good
    assert _wheel(good) == []


def test_tests_a_missing_door_and_a_wrong_name_are_named():
    good = sorted(check_dist.package_files()) + [INFO + "METADATA"]
    assert _wheel(good + ["tests/test_store.py"]) == ["wheel: tests/test_store.py should not ship",
                                                      "wheel: tests/test_store.py outside corl/ and its dist-info"]
    assert _wheel([n for n in good if n != "corl/tasks/door/scene.py"]) == ["wheel: corl/tasks/door/scene.py missing"]
    assert _wheel(good + ["corl/__pycache__/x.cpython-311.pyc"])[0].endswith("should not ship")
    wrong = check_dist.check_wheel(good, METADATA.replace("corl-skills", "corl"), "", check_dist.package_files(),
                                   RELEASE)
    assert wrong == ["wheel: METADATA does not name the distribution corl-skills",
                     "wheel: no console script corl = corl.cli:main"]


def test_an_sdist_without_tests_and_with_the_changelog_passes():
    top = f"corl_skills-{RELEASE}/"
    files = [top + f"src/{n}" for n in check_dist.package_files()]
    files += [top + n for n in ("pyproject.toml", "README.md", "LICENSE", "CHANGELOG.md", "constraints.txt",
                                "MANIFEST.in", "examples/planar_button.py")]
    assert check_dist.check_sdist(files, check_dist.package_files(), RELEASE) == []
    bad = check_dist.check_sdist(files + [top + "tests/test_store.py"], check_dist.package_files(), RELEASE)
    assert bad == ["sdist: tests/test_store.py should not ship"]
