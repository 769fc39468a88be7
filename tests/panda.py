"""The Panda example's tests run where the Panda's URDF ships (example-robot-data 6.0.0) and MuJoCo imports."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # examples/ is imported as a package from the repository root
    sys.path.insert(0, str(ROOT))


def has_panda() -> bool:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    from corl.errors import InputError
    from corl.mujoco import example_robot_dir

    try:
        return (example_robot_dir("panda_description") / "urdf" / "panda.urdf").is_file()
    except InputError:
        return False


needs_panda = pytest.mark.skipif(not has_panda(), reason="the Panda ships in example-robot-data 6.0.0 (and needs mujoco)")
