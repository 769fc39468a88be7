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

__all__ = ["add_force_sensor", "ForceSensor", "remove_static_load", "contact_force", "touching"]


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


def touching(data, geoms_a: Sequence[int], geoms_b: Sequence[int]) -> bool:
    """Whether any geom of ``geoms_a`` is in contact with any geom of ``geoms_b``."""
    ncon = data.ncon
    if ncon == 0:
        return False
    a, b = _ids(geoms_a), _ids(geoms_b)
    geoms = data.contact.geom[:ncon]
    return bool(np.any((np.isin(geoms[:, 0], a) & np.isin(geoms[:, 1], b))
                       | (np.isin(geoms[:, 1], a) & np.isin(geoms[:, 0], b))))


def contact_force(model, data, geoms_a: Sequence[int], geoms_b: Sequence[int]) -> np.ndarray:
    """Total contact force (3,) in the world frame that ``geoms_b`` exert on ``geoms_a`` (N).

    Sums ``mj_contactForce`` (normal and friction, contact frame) over the contacts between the two
    sets, rotated to the world frame; zero when they do not touch.
    """
    import mujoco

    a, b = _ids(geoms_a), _ids(geoms_b)
    total = np.zeros(3)
    ncon = data.ncon
    if ncon == 0:
        return total
    wrench = np.zeros(6)
    geoms = data.contact.geom[:ncon]
    for i in np.flatnonzero((np.isin(geoms[:, 0], a) & np.isin(geoms[:, 1], b))
                            | (np.isin(geoms[:, 1], a) & np.isin(geoms[:, 0], b))):
        mujoco.mj_contactForce(model, data, int(i), wrench)
        frame = data.contact.frame[i].reshape(3, 3)  # rows: normal (from geom1 to geom2), tangents
        f_world = frame.T @ wrench[:3]  # force on geom2 from geom1, world frame
        total += f_world if np.isin(geoms[i, 1], a) else -f_world
    return total
