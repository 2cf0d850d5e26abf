"""The collision world of one environment: the car, boxes and bot cars, in PyBullet when near.

One ``BulletClient`` per world, never the global ``pybullet`` connection, so environments in one
process stay independent. Bodies are posed each control step by the simulator (the car and bots
move kinematically); the world answers which bodies the car touches and what the lidar's rays hit.

PyBullet is asked only when an obstacle is within reach: of the car's body (touching) or of the
lidar's range (seen), each body taken as the circle round its footprint, with a margin beyond
Bullet's contact threshold. Otherwise the answer is known without it (nothing touched, every ray
at its range), so the world connects to PyBullet, importing it, only once something comes near.
A time trial, and a race whose car never nears a box (reward validation's sample situations),
runs on a machine without PyBullet (no wheel is published for every Python: the device machine's
3.12 has none).
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence what PyBullet's C code prints on import and on connecting,
    which would otherwise land in every worker's log for every environment."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    try:
        with open(os.devnull, "wb") as devnull:
            for fd in saved:
                os.dup2(devnull.fileno(), fd)
        yield
    finally:
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)


class WorldUnavailable(RuntimeError):
    """PyBullet, which boxes and bot cars need, cannot be imported on this machine."""


UNAVAILABLE = (
    "Object avoidance and head-to-bot races need PyBullet, which is not installed on this "
    "simulation machine; time trials run without it."
)
_missing = False  # PyBullet was looked for and not found: a sealed process cannot look again


def _import_pybullet():
    """The ``pybullet`` module and its ``BulletClient``, imported quietly on first use."""
    global _missing
    if _missing:
        raise WorldUnavailable(UNAVAILABLE)
    try:
        with _quiet_stdout():
            import pybullet
            from pybullet_utils.bullet_client import BulletClient
    except ImportError as error:
        _missing = True
        raise WorldUnavailable(UNAVAILABLE) from error
    return pybullet, BulletClient


# [m] beyond the footprints' circles within which Bullet is asked: its contact points come from
# within its contact breaking threshold (0.02 m by default), well inside this.
CONTACT_MARGIN = 0.1


@dataclass
class _Body:
    half: tuple[float, float, float]  # [m] half its length, width and height
    mass: float
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x, y [m] of its middle, yaw [rad]
    bullet: int | None = None  # its body in PyBullet, once connected

    @property
    def radius(self) -> float:
        """[m] of the circle round its footprint."""
        return math.hypot(self.half[0], self.half[1])

    def within(self, x: float, y: float, reach: float) -> bool:
        """Whether its footprint may come within ``reach`` of (x, y)."""
        return math.hypot(self.pose[0] - x, self.pose[1] - y) <= reach + self.radius


class World:
    def __init__(self) -> None:
        self._bodies: list[_Body] = []
        self._obstacles: list[int] = []
        self._client = None  # PyBullet's, once something comes near
        self._box_shape: int | None = None
        self._by_bullet: dict[int, int] = {}  # PyBullet's body ids: ours
        self.car: int | None = None

    def add_car(self, length: float, width: float, height: float) -> int:
        """The agent's car: a dynamic body, so Bullet reports its contacts with static ones."""
        self.car = self._add_box(length, width, height, mass=1.0)
        return self.car

    def add_obstacle(self, length: float, width: float, height: float) -> int:
        """A box or a bot car: something the car can hit and the lidar can see."""
        body = self._add_box(length, width, height, mass=0.0)
        self._obstacles.append(body)
        return body

    def _add_box(self, length: float, width: float, height: float, *, mass: float) -> int:
        self._bodies.append(_Body((length / 2, width / 2, height / 2), mass))
        if self._client is not None:
            self._add_to_bullet(len(self._bodies) - 1)
        return len(self._bodies) - 1

    def place(self, body: int, x: float, y: float, yaw: float) -> None:
        """Pose a body by the middle of its footprint and its heading [rad]."""
        self._bodies[body].pose = (x, y, yaw)
        if self._client is not None:
            self._place_in_bullet(self._bodies[body])

    def car_touches(self) -> list[int]:
        """The obstacles the car's body overlaps now."""
        car = self._bodies[self.car]
        reach = car.radius + CONTACT_MARGIN
        if not any(
            self._bodies[o].within(car.pose[0], car.pose[1], reach) for o in self._obstacles
        ):
            return []
        client = self._bullet()
        client.performCollisionDetection()
        contacts = client.getContactPoints(bodyA=car.bullet)
        return sorted({self._by_bullet[contact[2]] for contact in contacts})

    def cast_rays(
        self, origin: Sequence[float], directions: np.ndarray, max_range: float
    ) -> np.ndarray:
        """Distances [m] along horizontal rays from ``origin`` (x, y, z) to the first obstacle,
        ``max_range`` where a ray hits nothing; the car itself is not seen."""
        x, y = origin[0], origin[1]
        if not any(
            self._bodies[o].within(x, y, max_range + CONTACT_MARGIN) for o in self._obstacles
        ):
            return np.full(len(directions), max_range)
        client = self._bullet()
        starts = np.tile(origin, (len(directions), 1))
        ends = starts.copy()
        ends[:, :2] += directions * max_range
        hits = client.rayTestBatch(starts.tolist(), ends.tolist())
        car = self._bodies[self.car].bullet if self.car is not None else None
        fractions = np.array(
            [hit[2] if hit[0] not in (-1, car) else 1.0 for hit in hits], dtype=np.float64
        )
        return fractions * max_range

    def connect(self) -> None:
        """Connect to PyBullet now, importing it, rather than once something comes near: a
        process that seals itself (a sandbox child) can open no file afterwards, neither
        PyBullet's nor /dev/null to quiet it. ``WorldUnavailable`` where it is not installed
        (and each time the world needs it from then on, without looking again)."""
        self._bullet()

    def _bullet(self):
        """The PyBullet client, connected (and PyBullet imported) on first need, with every body
        added and posed."""
        if self._client is None:
            pybullet, bullet_client = _import_pybullet()
            with _quiet_stdout():
                self._client = bullet_client(connection_mode=pybullet.DIRECT)
            self._client.setGravity(0, 0, 0)
            self._box_shape = pybullet.GEOM_BOX
            for index in range(len(self._bodies)):
                self._add_to_bullet(index)
        return self._client

    def _add_to_bullet(self, index: int) -> None:
        body = self._bodies[index]
        shape = self._client.createCollisionShape(self._box_shape, halfExtents=list(body.half))
        body.bullet = self._client.createMultiBody(
            baseMass=body.mass, baseCollisionShapeIndex=shape
        )
        self._by_bullet[body.bullet] = index
        self._place_in_bullet(body)

    def _place_in_bullet(self, body: _Body) -> None:
        x, y, yaw = body.pose
        self._client.resetBasePositionAndOrientation(
            body.bullet, [x, y, body.half[2]], [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]
        )

    def close(self) -> None:
        if self._client is not None:
            self._client.disconnect()
            self._client = None
