"""ContactPairs, touching and contact_force against plain loops over the contacts, on real contacts."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from corl.errors import InputError
from corl.mujoco import contact_force, touching
from corl.mujoco.forces import ContactPairs

mujoco = pytest.importorskip("mujoco")


def plain_touching(data, a, b) -> bool:
    """Any contact with one geom in ``a`` and the other in ``b``: a loop over Python sets."""
    a, b = set(a), set(b)
    pairs = data.contact.geom[:data.ncon].tolist()
    return any((g1 in a and g2 in b) or (g2 in a and g1 in b) for g1, g2 in pairs)


def plain_force(model, data, a, b) -> np.ndarray:
    """The old contact_force: a loop over the contacts, the sign from the second geom's set."""
    a, b = set(a), set(b)
    total, wrench = np.zeros(3), np.zeros(6)
    for i in range(data.ncon):
        g1, g2 = (int(g) for g in data.contact.geom[i])
        if (g1 in a and g2 in b) or (g2 in a and g1 in b):
            mujoco.mj_contactForce(model, data, i, wrench)
            f_world = data.contact.frame[i].reshape(3, 3).T @ wrench[:3]
            total += f_world if g2 in a else -f_world
    return total


@pytest.fixture(scope="module")
def door():
    from corl.tasks.door.demo import scripted_demonstration
    from corl.tasks.door.scene import load_scene

    scene = load_scene()
    return scene, scripted_demonstration(scene)


def _door_states(door, every: int = 25):
    """MjData copies along the demonstration's trial, every ``every`` steps (about 100 of them)."""
    from corl.tasks.door.sim import rollout

    scene, demo = door
    states = []

    def keep(t, data):
        states.append(copy.copy(data))  # MjData.__copy__: mj_copyData

    rollout(demo.reference(), t_contact=demo.t_contact, scene=scene, frame_every=every, on_frame=keep)
    return states


def test_contact_pairs_match_the_plain_loop_on_the_door(door):
    scene, _ = door
    model = scene.model
    states = _door_states(door)
    assert sum(d.ncon > 0 for d in states) > 20  # the pads, palm and door do touch
    rng = np.random.default_rng(0)
    sets = [(scene.tip_geoms, scene.handle_geoms), (scene.handle_geoms, scene.tip_geoms),
            (scene.palm_geoms, scene.door_geoms),
            (scene.tip_geoms + scene.palm_geoms, scene.door_geoms + scene.handle_geoms)]
    sets += [tuple(rng.choice(model.ngeom, size=k, replace=False) for k in rng.integers(1, 8, size=2))
             for _ in range(20)]
    hits = 0
    for a, b in sets:
        pairs = ContactPairs(model, a, b)
        for data in states:
            expected = plain_touching(data, a, b)
            hits += expected
            assert pairs(data) is expected
            assert touching(data, a, b) is expected
            force = plain_force(model, data, a, b)
            assert np.array_equal(pairs.force(data), force)  # bit for bit
            assert np.array_equal(contact_force(model, data, a, b), force)
    assert hits > 50


def test_match_takes_stacked_contacts_and_the_flex_id(door):
    scene, _ = door
    pairs = ContactPairs(scene.model, scene.tip_geoms, scene.handle_geoms)
    tip, bar = scene.tip_geoms[0], scene.handle_geoms[0]
    geoms = np.array([[tip, bar], [bar, tip], [tip, tip], [-1, bar], [tip, -1], [0, 1]], dtype=np.int32)
    assert pairs.match(geoms).tolist() == [True, True, False, False, False, False]
    assert pairs.match(np.zeros((0, 2), dtype=np.int32)).shape == (0,)


def test_contact_pairs_refuse_ids_outside_the_model(door):
    scene, _ = door
    with pytest.raises(InputError, match="not in the model"):
        ContactPairs(scene.model, [scene.model.ngeom], scene.handle_geoms)
    with pytest.raises(InputError, match="non-empty"):
        ContactPairs(scene.model, [], scene.handle_geoms)


def test_one_off_functions_keep_their_old_leniency(arm):
    model = arm.model
    data = mujoco.MjData(model)
    for _ in range(500):  # the crate settles on the floor
        mujoco.mj_step(model, data)
    crate, floor = [arm.id("geom", "crate")], [arm.id("geom", "floor")]
    assert touching(data, crate, floor) and touching(data, floor + [999], crate)  # unknown ids match nothing
    assert np.array_equal(contact_force(model, data, crate + [999], floor), plain_force(model, data, crate, floor))
