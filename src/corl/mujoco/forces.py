"""Force readings: a force-torque sensor at a site, and the contact force between two sets of geoms.

Glossary
--------
f_raw     (3,) what MuJoCo's force sensor at a site reads: the force the site's parent exerts on
          the subtree below it, in the site frame (N)
m         mass (kg) of the subtree below the sensor; at rest the sensor reads its weight
f         (3,) interaction force: ``f_raw`` minus the static weight ``m g`` in the site frame
F_ab      (3,) total contact force (world frame, N) that geoms ``b`` exert on geoms ``a``

The static-load correction leaves the inertial forces of the hand in ``f`` (as a real wrist sensor
that is zeroed at rest does); the contact force sums ``mj_contactForce`` over the active contacts.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from corl.errors import InputError
from corl.mujoco.parse import check_spec
from corl.mujoco.robot import Robot

__all__ = ["add_force_sensor", "ForceSensor", "remove_static_load", "ContactPairs", "contact_force", "touching"]


def add_force_sensor(spec, site: str) -> tuple[str, str]:
    """Add force and torque sensors ``<site>_force`` / ``<site>_torque`` at an existing site of
    ``spec`` (a mujoco.MjSpec). Returns their names."""
    import mujoco

    check_spec(spec, "add_force_sensor")
    if not (isinstance(site, str) and site and spec.site(site) is not None):
        sites = [s.name for s in spec.sites if s.name]
        raise InputError(f"no site {site!r} in the spec; add it first (body.add_site(name=...)); its sites are {sites}")
    names = (f"{site}_force", f"{site}_torque")
    if any(spec.sensor(n) is not None for n in names):
        raise InputError(f"site {site!r} has a force sensor already ({names[0]}); add it once")
    spec.add_sensor(name=names[0], type=mujoco.mjtSensor.mjSENS_FORCE, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)
    spec.add_sensor(name=names[1], type=mujoco.mjtSensor.mjSENS_TORQUE, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site)
    return names


def remove_static_load(force_raw: np.ndarray, rotations: np.ndarray, mass: float, gravity: np.ndarray) -> np.ndarray:
    """Interaction forces (K, 3) from raw sensor forces (K, 3) in the site frame.

    Parameters
    ----------
    force_raw : (K, 3) the sensor's readings.
    rotations : (K, 3, 3) the site's world orientations at the readings.
    mass : kg below the sensor.
    gravity : (3,) the model's gravity (``model.opt.gravity``).

    Notes
    -----
    The sensor reads ``m g`` (world -z) as the force the parent holds the subtree with, i.e.
    ``+m |g| z_world`` expressed in the site frame; that is subtracted.
    """
    weight = np.array([0.0, 0.0, mass * -gravity[2]])
    return force_raw - np.einsum("kji,j->ki", rotations, weight)


class ForceSensor:
    """A force(-torque) sensor at a site added by :func:`add_force_sensor`.

    Parameters
    ----------
    robot : Robot (its model has the sensors)
    site : the site's name
    """

    def __init__(self, robot: Robot, site: str) -> None:
        model = robot.model
        self.site = robot.id("site", site)
        self.force_adr = int(model.sensor_adr[robot.id("sensor", f"{site}_force")])
        torque = f"{site}_torque"
        try:
            self.torque_adr = int(model.sensor_adr[robot.id("sensor", torque)])
        except InputError:
            self.torque_adr = None
        self.body = int(model.site_bodyid[self.site])
        self.mass = float(model.body_subtreemass[self.body])
        self.gravity = np.array(model.opt.gravity)

    def raw(self, data) -> np.ndarray:
        """The sensor's force reading (3,), site frame, N."""
        return data.sensordata[self.force_adr : self.force_adr + 3].copy()

    def torque(self, data) -> np.ndarray:
        """The torque reading (3,), site frame, Nm."""
        if self.torque_adr is None:
            raise InputError("this sensor has no torque channel; add it with add_force_sensor")
        return data.sensordata[self.torque_adr : self.torque_adr + 3].copy()

    def rotation(self, data) -> np.ndarray:
        """The site's world orientation (3, 3)."""
        return data.site_xmat[self.site].reshape(3, 3).copy()

    def interaction(self, data) -> np.ndarray:
        """Interaction force (3,) in the site frame: the reading minus the static weight below it."""
        return remove_static_load(self.raw(data)[None], self.rotation(data)[None], self.mass, self.gravity)[0]


def _ids(geoms) -> np.ndarray:
    ids = np.atleast_1d(np.asarray(geoms, dtype=int))
    if ids.ndim != 1 or ids.size == 0:
        raise InputError(f"give geom ids as a non-empty sequence, got {geoms!r}")
    return ids


class ContactPairs:
    """The contacts between two sets of geoms, found with tables built once (the hot-path form of
    :func:`touching` and :func:`contact_force`, for a check every few simulation steps).

    Parameters
    ----------
    model : mujoco.MjModel
    geoms_a, geoms_b : geom ids (each a non-empty sequence of ids in ``[0, model.ngeom)``).

    Notes
    -----
    ``ContactPairs(model, a, b)(data)`` is ``touching(data, a, b)``; ``.force(data)`` is
    ``contact_force(model, data, a, b)``, bit for bit. Each id of ``a`` and ``b`` gets a compact
    number (0 for every other geom, and for the -1 that a flex contact has in ``geom``); a
    ``(m + 1, m + 1)`` table over them says which pairs count, so a check is two gathers over
    ``data.contact.geom``: about 3 us, where four ``np.isin`` took about 50 us (and the one-off
    :func:`touching`, which sorts nothing either, about 9 us). :meth:`match` also takes the
    contacts of many steps stacked, to check them all after a simulation.
    """

    def __init__(self, model, geoms_a: Sequence[int], geoms_b: Sequence[int]) -> None:
        a, b = _ids(geoms_a), _ids(geoms_b)
        n = int(model.ngeom)
        bad = [int(g) for g in np.concatenate([a, b]) if not 0 <= g < n]
        if bad:
            raise InputError(f"geom ids {bad} are not in the model (it has {n} geoms, ids 0..{n - 1})")
        self.model = model
        both = np.union1d(a, b)
        self._compact = np.zeros(n + 1, dtype=np.intp)  # entry n: the id -1 of a flex contact
        self._compact[both] = np.arange(1, both.size + 1)
        in_a = np.zeros(both.size + 1, dtype=bool)
        in_b = np.zeros(both.size + 1, dtype=bool)
        in_a[self._compact[a]] = True
        in_b[self._compact[b]] = True
        self._in_a = in_a  # (m + 1,) by compact number: is it a geom of a
        self._pair = (in_a[:, None] & in_b[None, :]) | (in_b[:, None] & in_a[None, :])  # (m + 1, m + 1)

    def match(self, geoms: np.ndarray) -> np.ndarray:
        """Which geom pairs (C, 2) join the two sets, (C,) bool: the rows of ``data.contact.geom``,
        or those of many steps stacked."""
        c = self._compact[geoms]
        return self._pair[c[:, 0], c[:, 1]]

    def __call__(self, data) -> bool:
        """Whether any geom of ``a`` touches any geom of ``b`` in ``data`` now."""
        if data.ncon == 0:
            return False
        return bool(self.match(data.contact.geom).any())

    def force(self, data) -> np.ndarray:
        """Total contact force (3,) in the world frame that ``b`` exerts on ``a`` (N); see
        :func:`contact_force`."""
        if data.ncon == 0:
            return np.zeros(3)
        geoms = data.contact.geom
        rows = np.flatnonzero(self.match(geoms))
        return _sum_forces(self.model, data, rows, self._in_a[self._compact[geoms[rows, 1]]])


def _sum_forces(model, data, rows: np.ndarray, b_side_in_a: np.ndarray) -> np.ndarray:
    """Sum of the world-frame forces (3,) of contacts ``rows`` (R,) on their ``a`` side;
    ``b_side_in_a`` (R,) says whether the contact's second geom is the one of ``a``."""
    import mujoco

    total = np.zeros(3)
    wrench = np.zeros(6)
    frames = data.contact.frame
    for i, flip in zip(rows, b_side_in_a):
        mujoco.mj_contactForce(model, data, int(i), wrench)
        frame = frames[i].reshape(3, 3)  # rows: normal (from geom1 to geom2), tangents
        f_world = frame.T @ wrench[:3]  # force on geom2 from geom1, world frame
        total += f_world if flip else -f_world
    return total


def _member(geoms: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """``np.isin(geoms, ids)`` for a few ids: one broadcast comparison, no sort."""
    return (geoms[..., None] == ids).any(axis=-1)


def touching(data, geoms_a: Sequence[int], geoms_b: Sequence[int]) -> bool:
    """Whether any geom of ``geoms_a`` is in contact with any geom of ``geoms_b``.

    A one-off check; to check every few steps, build a :class:`ContactPairs` once.
    """
    ncon = data.ncon
    if ncon == 0:
        return False
    a, b = _ids(geoms_a), _ids(geoms_b)
    geoms = data.contact.geom[:ncon]
    in_a, in_b = _member(geoms, a), _member(geoms, b)
    return bool(np.any((in_a[:, 0] & in_b[:, 1]) | (in_a[:, 1] & in_b[:, 0])))


def contact_force(model, data, geoms_a: Sequence[int], geoms_b: Sequence[int]) -> np.ndarray:
    """Total contact force (3,) in the world frame that ``geoms_b`` exert on ``geoms_a`` (N).

    Sums ``mj_contactForce`` (normal and friction, contact frame) over the contacts between the two
    sets, rotated to the world frame; zero when they do not touch. A one-off call; to sum every few
    steps, build a :class:`ContactPairs` once and call its ``force``.
    """
    a, b = _ids(geoms_a), _ids(geoms_b)
    ncon = data.ncon
    if ncon == 0:
        return np.zeros(3)
    geoms = data.contact.geom[:ncon]
    in_a, in_b = _member(geoms, a), _member(geoms, b)
    rows = np.flatnonzero((in_a[:, 0] & in_b[:, 1]) | (in_a[:, 1] & in_b[:, 0]))
    return _sum_forces(model, data, rows, in_a[rows, 1])
