"""The settings an environment accepts, checked and normalised, with errors a racer understands.

The forms follow DeepRacer's ``model_metadata.json``: sensors by their DeepRacer names, and the
action space as a list of ``{"steering_angle", "speed"}`` (discrete) or as ranges (continuous).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

CAMERAS = ("FRONT_FACING_CAMERA", "STEREO_CAMERAS")
LIDARS = ("SECTOR_LIDAR", "LIDAR")
RACE_TYPES = ("TIME_TRIAL", "OBJECT_AVOIDANCE", "HEAD_TO_BOT")
MODES = ("training", "evaluation")
MAX_STEERING = 30.0  # [deg]
SPEED_RANGE = (0.1, 4.0)  # [m/s]
MAX_OBJECTS = 6
BOT_SPEED_RANGE = (0.2, 6.0)  # [m/s]

DEFAULT_ACTION_SPACE = tuple(
    {"steering_angle": float(steering), "speed": speed}
    for speed in (0.5, 1.0)
    for steering in (-30, -15, 0, 15, 30)
)


class ConfigError(ValueError):
    """A setting out of range or malformed; the message names it and says what is allowed."""


@dataclass(frozen=True)
class DiscreteActions:
    actions: tuple[tuple[float, float], ...]  # (steering [deg], speed [m/s]) per action index

    def metadata(self) -> list[dict]:
        return [
            {"steering_angle": steering, "speed": speed, "index": index}
            for index, (steering, speed) in enumerate(self.actions)
        ]


@dataclass(frozen=True)
class ContinuousActions:
    steering: tuple[float, float]  # [deg] low, high
    speed: tuple[float, float]  # [m/s] low, high

    def scale(self, action: Sequence[float]) -> tuple[float, float]:
        """Steering and speed from a policy's action in [-1, 1]², clipped to the ranges."""
        a = [min(max(float(v), -1.0), 1.0) for v in action[:2]]
        steering = self.steering[0] + (a[0] + 1) / 2 * (self.steering[1] - self.steering[0])
        speed = self.speed[0] + (a[1] + 1) / 2 * (self.speed[1] - self.speed[0])
        return steering, speed

    def metadata(self) -> dict:
        return {
            "steering_angle": {"low": self.steering[0], "high": self.steering[1]},
            "speed": {"low": self.speed[0], "high": self.speed[1]},
        }


@dataclass(frozen=True)
class Objects:
    count: int = 3
    randomize: bool = False  # new positions every episode, or fixed along the lap


@dataclass(frozen=True)
class Bots:
    count: int = 3
    speed: float = 0.5  # [m/s]
    lane_changes: bool = False


@dataclass(frozen=True)
class Penalties:
    off_track: float = 2.0  # [s]
    crash: float = 5.0  # [s]


def sensors(value: Sequence[str]) -> tuple[str, str | None]:
    """(camera, lidar or None) from a DeepRacer sensor list."""
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ConfigError('Sensors are a list such as ["FRONT_FACING_CAMERA", "SECTOR_LIDAR"].')
    unknown = [name for name in value if name not in CAMERAS + LIDARS]
    if unknown:
        raise ConfigError(
            f"Unknown sensor {unknown[0]!r}; choose from {', '.join(CAMERAS + LIDARS)}."
        )
    cameras = [name for name in value if name in CAMERAS]
    lidars = [name for name in value if name in LIDARS]
    if len(cameras) != 1:
        raise ConfigError("A car needs exactly one camera: FRONT_FACING_CAMERA or STEREO_CAMERAS.")
    if len(lidars) > 1:
        raise ConfigError("A car can carry at most one lidar: SECTOR_LIDAR or LIDAR.")
    return cameras[0], lidars[0] if lidars else None


def action_space(value) -> DiscreteActions | ContinuousActions:
    if value is None:
        value = DEFAULT_ACTION_SPACE
    if isinstance(value, Mapping):
        try:
            steering = (
                float(value["steering_angle"]["low"]),
                float(value["steering_angle"]["high"]),
            )
            speed = (float(value["speed"]["low"]), float(value["speed"]["high"]))
        except (KeyError, TypeError, ValueError):
            raise ConfigError(
                'A continuous action space is {"steering_angle": {"low": -30, "high": 30}, '
                '"speed": {"low": 1, "high": 2}}.'
            ) from None
        _check_steering(*steering)
        _check_speed(*speed)
        if steering[0] >= steering[1] or speed[0] >= speed[1]:
            raise ConfigError("In a continuous action space each low must be below its high.")
        return ContinuousActions(steering=steering, speed=speed)
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ConfigError("The action space is a list of actions or a pair of ranges.")
    if not 2 <= len(value) <= 30:
        raise ConfigError(f"A discrete action space has 2 to 30 actions, not {len(value)}.")
    actions = []
    for number, action in enumerate(value, start=1):
        try:
            steering, speed = float(action["steering_angle"]), float(action["speed"])
        except (KeyError, TypeError, ValueError):
            raise ConfigError(
                f'Action {number} must have a numeric "steering_angle" and "speed".'
            ) from None
        _check_steering(steering, where=f"action {number}")
        _check_speed(speed, where=f"action {number}")
        actions.append((steering, speed))
    if len(set(actions)) != len(actions):
        raise ConfigError("Two actions of the action space are the same.")
    return DiscreteActions(tuple(actions))


def choice(name: str, value: str, allowed: Sequence[str]) -> str:
    if value not in allowed:
        raise ConfigError(f"{name} must be one of {', '.join(allowed)}, not {value!r}.")
    return value


def objects(value, race_type: str) -> Objects | None:
    if race_type != "OBJECT_AVOIDANCE":
        if value:
            raise ConfigError("Boxes are placed only in an OBJECT_AVOIDANCE race.")
        return None
    settings = Objects(**_fields(value, Objects, "objects"))
    _check_count(settings.count, "boxes")
    return settings


def bots(value, race_type: str) -> Bots | None:
    if race_type != "HEAD_TO_BOT":
        if value:
            raise ConfigError("Bot cars race only in a HEAD_TO_BOT race.")
        return None
    settings = Bots(**_fields(value, Bots, "bots"))
    _check_count(settings.count, "bot cars")
    low, high = BOT_SPEED_RANGE
    if not low <= settings.speed <= high:
        raise ConfigError(f"Bot cars drive at {low}-{high} m/s, not {settings.speed}.")
    return settings


def penalties(value) -> Penalties:
    settings = Penalties(**_fields(value, Penalties, "penalties"))
    for name in ("off_track", "crash"):
        seconds = getattr(settings, name)
        if not (isinstance(seconds, int | float) and 0 <= seconds <= 60):
            raise ConfigError(
                f"The {name.replace('_', '-')} penalty is 0-60 seconds, not {seconds}."
            )
    return settings


def positive_int(name: str, value, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(f"{name} must be a whole number from {low} to {high}, not {value!r}.")
    return value


def fraction(name: str, value) -> float:
    if not isinstance(value, int | float) or not 0 <= value < 1 or math.isnan(value):
        raise ConfigError(f"{name} is a fraction of the lap, from 0 up to (not including) 1.")
    return float(value)


def _fields(value, kind, name: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ConfigError(f"The {name} settings are a mapping such as {kind()}.")
    allowed = set(kind.__dataclass_fields__)
    unknown = set(value) - allowed
    if unknown:
        raise ConfigError(
            f"Unknown {name} setting {sorted(unknown)[0]!r}; use {', '.join(sorted(allowed))}."
        )
    return dict(value)


def _check_count(count, what: str) -> None:
    positive_int(f"The number of {what}", count, 1, MAX_OBJECTS)


def _check_steering(*angles: float, where: str = "the action space") -> None:
    for angle in angles:
        if not -MAX_STEERING <= angle <= MAX_STEERING:
            raise ConfigError(
                f"Steering in {where} is {-MAX_STEERING:g} to {MAX_STEERING:g} degrees, "
                f"not {angle:g}."
            )


def _check_speed(*speeds: float, where: str = "the action space") -> None:
    low, high = SPEED_RANGE
    for speed in speeds:
        if not low <= speed <= high:
            raise ConfigError(f"Speed in {where} is {low:g} to {high:g} m/s, not {speed:g}.")
