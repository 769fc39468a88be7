"""The door's scene and scripted demonstration, shared by the door's test modules (built once each)."""

import pytest


@pytest.fixture(scope="module")
def scene():
    pytest.importorskip("mujoco")
    from corl.tasks.door.scene import load_scene

    return load_scene()


@pytest.fixture(scope="module")
def demo(scene):
    from corl.tasks.door.demo import scripted_demonstration

    return scripted_demonstration(scene)
