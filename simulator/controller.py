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
        spec = self.env.car.spec
        here, error, offset, speed = self._errors()
        wanted = (
            math.atan(spec.wheelbase * self._bend_ahead(here, speed))
            + self.heading_gain * error
            + math.atan2(-self.gain * offset, speed)
        )
        # Beyond the angle whose turn the grip can hold, the front tyres only slide.
        grip = math.atan(spec.wheelbase * spec.friction * GRAVITY / speed**2)
        return self._command(max(-grip, min(grip, wanted)))

    def _errors(self) -> tuple[float, float, float, float]:
        """Where the front axle is on the path ([m] along it), the car's heading error from the
        path's there [rad, left positive], the axle's offset [m, left of the path positive], and
        the speed [m/s] the control law divides by (at least 0.3 m/s)."""
        car = self.env.car
        where = self.path.project_points([car.point_ahead(car.spec.wheelbase)])
        here = float(where.distance[0])
        _, _, heading = self.path.point_at(here)
        offset = float(where.offset[0]) * (1.0 if where.is_left[0] else -1.0)
        error = math.atan2(math.sin(float(heading) - car.yaw), math.cos(float(heading) - car.yaw))
        return here, error, offset, max(car.speed, 0.3)

    def _bend_ahead(self, here: float, speed: float) -> float:
        """[1/m] the path's curvature where the car will be ``anticipation`` seconds on."""
        ahead = here + speed * self.anticipation
        return float(self.curvature[int(ahead / self.SPACING) % len(self.curvature)])

    def _command(self, angle: float) -> float:
        """[deg] the command that turns the wheels to ``angle`` [rad] by the end of the step: the
        steering loop kicks the hinge at each change and closes the rest slowly (``Hinge``)."""
        car = self.env.car
        limit = math.radians(car.spec.max_steering)
        return math.degrees(car.hinge.command_for(angle, car.periods(self.env.dt), limit))

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
    centre line, at the line's speeds, which ask for 0.8 of the grip in the bends.

    Steering: the centre-line driver's law (Stanley's at the front axle, the curvature
    ``anticipation`` seconds ahead fed forward), nearer and firmer, with four changes that
    keep the car on a line taken at the grip's limit (with the centre-line driver's law it
    left 28 of the 122 built-in lines, in the long tracks' hairpins):

    - The bend is fed forward as the angle that takes the front axle round it, which the
      tracked point is, not the rear axle: asin rather than atan of wheelbase * curvature.
    - The heading gain falls with speed, to ``HEADING_RATE / speed``: a step turns the car by
      about speed * dt / wheelbase times the wheels' angle, so a fixed 0.8 turns out all of a
      heading error within a step at 3 m/s, and more above, and with the hinge's lag sets the
      car weaving from side to side, each swing taking grip; so it turns out 0.6 of it.
    - The offset's correction divides by the speed no lower than ``OFFSET_SPEED``: from a
      standing start on the centre line, off the racing line, a low speed would turn it to
      full lock and swing the car across.
    - The wheels are held within the grip's angle of the way the rear axle travels, not of the
      car's heading: when the rear steps out, the driver counter-steers.

    Speed: the line's speed due a step on, but no faster than the curvature the steering asks
    for (relative to the rear axle's travel, the lesser of this step's and the last) lets
    ``DEMAND_GRIP`` of mu * g hold, and never below ``LOWEST_CAP`` for it: a car that has run
    wide of the line brakes until it can steer back, where at the line's speed it had only a
    fifth of the grip to do it with and ran on off the track. The share is above 1 because the
    heading's and the offset's corrections last a step or two and the car rides them out; at
    1.0 it braked for them too often and lapped up to 5% slower than the line."""

    HEADING_RATE = 1.5  # [m/s] above 1.9 m/s the heading gain is this over the speed
    OFFSET_SPEED = 1.5  # [m/s] the least speed the offset's correction divides by
    DEMAND_GRIP = 1.2  # of mu * g, that the curvature the steering asks for may need
    LOWEST_CAP = 1.5  # [m/s] commanded, below which the steering's demand never slows the car

    def __init__(
        self,
        env: DeepRacerEnv,
        line: RacingLine,
        heading_gain: float = 0.8,
        anticipation: float = 0.15,
        **kw,
    ) -> None:
        # Nearer and firmer than on the centre line: the line's bends are tighter and taken at
        # the grip's limit (at 0.5 and 0.3 s the centre-line driver's law left 75 of the 122
        # built-in lines).
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
        self._demands = [0.0, 0.0]  # [1/m] the curvature asked for at the last step and this

    def steering(self) -> float:
        car = self.env.car
        spec = car.spec
        here, error, offset, speed = self._errors()
        # [rad] the way the rear axle travels, from the heading: its sideslip
        rear = math.atan2(car.lateral_speed - car.yaw_rate * spec.rear_to_centre, speed)
        # The wheels' angle that takes the front axle round the bend (the rear axle runs inside
        # it): sin(angle) = wheelbase / radius. The line's hairpins are as tight as 0.41 m, where
        # the rear axle's tan(angle) = wheelbase / radius is 2° short and the car ran wide.
        reach = spec.wheelbase * self._bend_ahead(here, speed)
        wanted = (
            math.asin(max(-1.0, min(1.0, reach)))
            + min(self.heading_gain, self.HEADING_RATE / speed) * error
            + math.atan2(-self.gain * offset, max(speed, self.OFFSET_SPEED))
        )
        turn = max(-1.4, min(1.4, wanted - rear))  # [rad] short of a right angle
        self._demands = [self._demands[1], math.tan(turn) / spec.wheelbase]
        grip = math.atan(spec.wheelbase * spec.friction * GRAVITY / speed**2)
        return self._command(max(rear - grip, min(rear + grip, wanted)))

    def target_speed(self) -> float:
        env, car = self.env, self.env.car
        spec = car.spec
        ahead = self.path.project_points([car.position]).distance[0] + car.speed * env.dt
        due = np.interp(ahead % self._along[-1], self._along, self._speeds)
        demand = min(abs(self._demands[0]), abs(self._demands[1]))
        held = math.sqrt(self.DEMAND_GRIP * spec.friction * GRAVITY / max(demand, 1e-6))
        cap = max(held / spec.wheel_target(1.0), self.LOWEST_CAP)
        return float(np.clip(min(due / spec.wheel_target(1.0), cap), spec.min_speed, self.speed))


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
