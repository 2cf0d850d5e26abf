"""The PyBullet world of one environment: collision bodies for the car, boxes and bot cars.

One ``BulletClient`` per world, never the global ``pybullet`` connection, so environments in one
process stay independent. Bodies are posed each control step by the simulator (the car and bots
move kinematically); the world answers which bodies the car touches and what the lidar's rays hit.

PyBullet is imported when the first world is made, not with this module: an environment makes a
world only where boxes or bot cars stand on the track, so a time trial runs on a machine that has
no PyBullet (no wheel is published for every Python: the device machine's 3.12 has none).
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator, Sequence

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


def _bullet():
    """The ``pybullet`` module and its ``BulletClient``, imported quietly on first use."""
    try:
        with _quiet_stdout():
            import pybullet
            from pybullet_utils.bullet_client import BulletClient
    except ImportError as error:
        raise WorldUnavailable(
            "Object avoidance and head-to-bot races need PyBullet, which is not installed on "
            "this simulation machine; time trials run without it."
        ) from error
    return pybullet, BulletClient


class World:
    def __init__(self) -> None:
        pybullet, bullet_client = _bullet()
        self._box_shape = pybullet.GEOM_BOX
        with _quiet_stdout():
            self._client = bullet_client(connection_mode=pybullet.DIRECT)
        self._client.setGravity(0, 0, 0)
        self._heights: dict[int, float] = {}
        self._obstacles: list[int] = []
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
        shape = self._client.createCollisionShape(
            self._box_shape, halfExtents=[length / 2, width / 2, height / 2]
        )
        body = self._client.createMultiBody(baseMass=mass, baseCollisionShapeIndex=shape)
        self._heights[body] = height
        return body

    def place(self, body: int, x: float, y: float, yaw: float) -> None:
        """Pose a body by the middle of its footprint and its heading [rad]."""
        self._client.resetBasePositionAndOrientation(
            body,
            [x, y, self._heights[body] / 2],
            [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)],
        )

    def car_touches(self) -> list[int]:
        """The obstacles the car's body overlaps now."""
        if not self._obstacles:
            return []
        self._client.performCollisionDetection()
        return sorted({contact[2] for contact in self._client.getContactPoints(bodyA=self.car)})

    def cast_rays(
        self, origin: Sequence[float], directions: np.ndarray, max_range: float
    ) -> np.ndarray:
        """Distances [m] along horizontal rays from ``origin`` (x, y, z) to the first obstacle,
        ``max_range`` where a ray hits nothing; the car itself is not seen."""
        if not self._obstacles:
            return np.full(len(directions), max_range)
        starts = np.tile(origin, (len(directions), 1))
        ends = starts.copy()
        ends[:, :2] += directions * max_range
        hits = self._client.rayTestBatch(starts.tolist(), ends.tolist())
        fractions = np.array(
            [hit[2] if hit[0] not in (-1, self.car) else 1.0 for hit in hits], dtype=np.float64
        )
        return fractions * max_range

    def close(self) -> None:
        if self._client is not None:
            self._client.disconnect()
            self._client = None
