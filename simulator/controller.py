"""A scripted driver that follows the centre line: a racer's first look at a track, and a check
that every track can be driven."""

from __future__ import annotations

import math

import numpy as np

from simulator.car import GRAVITY
from simulator.config import ContinuousActions
from simulator.env import DeepRacerEnv
from simulator.racing_line import RacingLine
from simulator.tracks import Track


class CentreLineDriver:
    """A scripted driver that follows the centre line at ``speed``.

    It steers as a path-following controller does (Stanley's, with the curvature ahead fed
    forward): the front axle is turned toward the centre line's heading (half the heading error:
    the whole of it, with the steering's kick, sets the car weaving), corrected by how far it is
    off the line, plus the steering that the curvature of the line ahead needs, read where the
    car will be ``anticipation`` seconds on. It commands what turns the wheels to that angle
    by the end of the step, as DeepRacer's steering loop moves them (``simulator.steering.Hinge``),
    as a racing policy learns to."""

    SPACING = 0.05  # [m] between the points where the centre line's curvature is known
    WINDOW = 0.25  # [m] on either side of a point, over which its curvature is measured

    def __init__(
        self,
        env: DeepRacerEnv,
        speed: float = 1.0,
        gain: float = 2.0,
        heading_gain: float = 0.5,
        anticipation: float = 0.3,
        path: Track | None = None,
    ) -> None:
        self.env = env
        self.speed = speed
        self.gain = gain  # [1/s] how fast an offset from the line is steered out
        self.heading_gain = heading_gain  # of the heading error, steered out at once
        self.anticipation = anticipation  # [s] ahead, where the curvature is read
        self.path = path or env.track  # the line followed: the centre line unless given
        self.curvature = curvature(self.path, self.SPACING, self.WINDOW)

    def steering(self) -> float:
        """[deg] the steering command, within ±30°."""
        env, car = self.env, self.env.car
        spec = car.spec
        front = car.point_ahead(spec.wheelbase)
        where = self.path.project_points([front])
        here = float(where.distance[0])
        _, _, heading = self.path.point_at(here)
        offset = float(where.offset[0]) * (1.0 if where.is_left[0] else -1.0)  # left of the line
        speed = max(car.speed, 0.3)
        ahead = here + speed * self.anticipation
        bend = float(self.curvature[int(ahead / self.SPACING) % len(self.curvature)])
        error = math.atan2(math.sin(float(heading) - car.yaw), math.cos(float(heading) - car.yaw))
        wanted = (
            math.atan(spec.wheelbase * bend)
            + self.heading_gain * error
            + math.atan2(-self.gain * offset, speed)
        )
        # Beyond the angle whose turn the grip can hold, the front tyres only slide.
        grip = math.atan(spec.wheelbase * spec.friction * GRAVITY / speed**2)
        wanted = max(-grip, min(grip, wanted))
        # The command that turns the wheels to that angle by the end of the step: the steering
        # loop kicks the hinge at each change and closes the rest slowly (``Hinge``).
        limit = math.radians(spec.max_steering)
        return math.degrees(car.hinge.command_for(wanted, car.periods(env.dt), limit))

    def target_speed(self) -> float:
        """[m/s] the speed to command now."""
        return self.speed

    def act(self):
        """The action, in the environment's action space, closest to steering at the target
        speed."""
        steering = self.steering()
        speed = self.target_speed()
        actions = self.env.actions
        if isinstance(actions, ContinuousActions):
            (s_low, s_high), (v_low, v_high) = actions.steering, actions.speed
            return np.array(
                [
                    2 * (steering - s_low) / (s_high - s_low) - 1,
                    2 * (speed - v_low) / (v_high - v_low) - 1,
                ],
                dtype=np.float32,
            )
        table = np.array(actions.actions)
        cost = np.abs(table[:, 0] - steering) / 30.0 + np.abs(table[:, 1] - speed)
        return int(np.argmin(cost))


class BrakingDriver(CentreLineDriver):
    """The centre-line driver with a racer's speed: as fast as the grip allows in each corner, up
    to ``speed``, braking before corners and accelerating out of them.

    The profile comes from the centre line's curvature and the car's friction: the highest speed
    whose centripetal acceleration a share (``grip``) of mu * g covers, then limited by the
    acceleration (forward pass) and braking (backward pass) that the same share allows."""

    def __init__(self, env: DeepRacerEnv, speed: float = 4.0, grip: float = 0.6, **kw) -> None:
        super().__init__(env, speed=speed, **kw)
        self.profile = speed_profile(self.curvature, env.car.spec, speed, grip, self.SPACING)

    def target_speed(self) -> float:
        env, car = self.env, self.env.car
        # The command acts over the next step: ask now for the speed due where the car will be.
        ahead = env.track.project_points([car.position]).distance[0] + car.speed * env.dt
        index = int(ahead / self.SPACING) % len(self.profile)
        return float(self.profile[index])


class RacingLineDriver(CentreLineDriver):
    """The path-following driver on a racing line (``simulator.racing_line``) rather than the
    centre line, at the line's speeds: it asks for the speed due where the car will be a step
    on, so it brakes into each bend as the line does."""

    def __init__(
        self,
        env: DeepRacerEnv,
        line: RacingLine,
        heading_gain: float = 0.8,
        anticipation: float = 0.15,
        **kw,
    ) -> None:
        # Nearer and firmer than on the centre line: the line's bends are tighter and taken at
        # the grip's limit (at 0.5 and 0.3 s the car left 75 of the 122 built-in lines).
        path = line.as_track(env.track)
        super().__init__(
            env,
            speed=float(line.speeds.max()),
            path=path,
            heading_gain=heading_gain,
            anticipation=anticipation,
            **kw,
        )
        self.line = line
        steps = np.hypot(*(np.roll(line.points, -1, axis=0) - line.points).T)
        self._along = np.concatenate([[0.0], np.cumsum(steps)])  # [m] to each point, and round
        self._speeds = np.append(line.speeds, line.speeds[0])

    def target_speed(self) -> float:
        env, car = self.env, self.env.car
        ahead = self.path.project_points([car.position]).distance[0] + car.speed * env.dt
        due = np.interp(ahead % self._along[-1], self._along, self._speeds)
        return float(np.clip(due / car.spec.wheel_target(1.0), car.spec.min_speed, self.speed))


def curvature(track, spacing: float, window: float) -> np.ndarray:
    """[1/m] the centre line's curvature every ``spacing`` metres, positive where it turns left:
    the turn between the chords ``window`` metres either side, whose middles are ``window``
    apart."""
    distances = np.arange(0.0, track.length, spacing)
    before = track.point_at(distances - window)
    after = track.point_at(distances + window)
    x, y, _ = track.point_at(distances)
    heading_in = np.arctan2(y - before[1], x - before[0])
    heading_out = np.arctan2(after[1] - y, after[0] - x)
    turn = np.angle(np.exp(1j * (heading_out - heading_in)))
    return turn / window


def speed_profile(bends: np.ndarray, spec, top: float, grip: float, spacing: float):
    """[m/s] the commanded speed at each point of ``bends`` (the centre line's curvature every
    ``spacing`` metres round the lap; see ``BrakingDriver``)."""
    usable = grip * spec.friction * GRAVITY  # [m/s²]
    rolling = spec.wheel_target(1.0)  # [m/s] rolled per 1 m/s commanded
    limit = np.sqrt(usable / np.maximum(np.abs(bends), 1e-6))
    speed = np.minimum(limit, spec.wheel_target(top))  # [m/s] rolled
    n = len(speed)
    for _ in range(2):  # twice round, so the limits carry over the start line
        for i in range(2 * n):  # accelerate out of corners
            j, k = i % n, (i - 1) % n
            speed[j] = min(speed[j], math.sqrt(speed[k] ** 2 + 2 * usable * spacing))
        for i in range(2 * n, 0, -1):  # brake before them
            j, k = i % n, (i + 1) % n
            speed[j] = min(speed[j], math.sqrt(speed[k] ** 2 + 2 * usable * spacing))
    return np.clip(speed / rolling, spec.min_speed, top)
