"""The settings an environment accepts, checked and normalised, with errors a racer understands.

The forms follow DeepRacer's ``model_metadata.json``: sensors by their DeepRacer names, and the
action space as a list of ``{"steering_angle", "speed"}`` (discrete) or as ranges (continuous).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TypeVar

# DeepRacer's control rate: the car acts, and a step is traced, 15 times a simulated second.
CONTROL_HZ = 15  # [Hz]
CAMERAS = ("FRONT_FACING_CAMERA", "STEREO_CAMERAS")
# The front camera's name in models of simapp before 2.0 (simapp
# bundle/markov/boto/s3/files/model_metadata.py:229-241, 01f5f01).
LEGACY_CAMERA = "observation"
LIDARS = ("SECTOR_LIDAR", "LIDAR")
MAX_CARS = 4  # on the track at once in a race of racers' models (simulator.head_to_head)
RACE_TYPES = ("TIME_TRIAL", "OBJECT_AVOIDANCE", "HEAD_TO_BOT")
MODES = ("training", "evaluation")
VIEWS = ("spectator", "camera")  # what a live viewer can watch (simulator.spectator.view_image)
MAX_STEERING = 30.0  # [deg]
SPEED_RANGE = (0.1, 4.0)  # [m/s]
MAX_OBJECTS = 6
BOT_SPEED_RANGE = (0.2, 6.0)  # [m/s]
# Resets an evaluation's episode may use before it ends. DeepRacer for Cloud sets 100
# (defaults/template-run.env:12, DR_EVAL_MAX_RESETS, 2eb1a1f); 10,000 is past what an episode
# of max_steps could use.
DEFAULT_MAX_RESETS = 100
MAX_RESETS = 10_000

DEFAULT_ACTION_SPACE = tuple(
    {"steering_angle": float(steering), "speed": speed}
    for speed in (0.5, 1.0)
    for steering in (-30, -15, 0, 15, 30)
)


class ConfigError(ValueError):
    """A setting out of range or malformed; the message names it and says what is allowed."""


class ActionSpaceError(ConfigError):
    """An action space with problems. ``problems`` maps each place to what is wrong there:
    ``""`` is the space as a whole; ``"<index>"`` a discrete action and ``"<index>.speed"`` or
    ``"<index>.steering_angle"`` one of its values, actions numbered from 0 as ``index`` is in
    ``model_metadata.json``; ``"speed.high"`` and the like a bound of a continuous range."""

    def __init__(self, problems: dict[str, str]) -> None:
        super().__init__(" ".join(problems.values()))
        self.problems = problems


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
    # [m/s] DeepRacer's: deepracer-simapp bundle/markov/agent_ctrl/bot_cars_agent_ctrl.py:39
    speed: float = 0.2
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
    """The action space from ``model_metadata.json``'s form; ``None`` gives DeepRacer's default.

    Every problem is reported at once, each at its place (``ActionSpaceError.problems``)."""
    if value is None:
        value = DEFAULT_ACTION_SPACE
    if isinstance(value, Mapping):
        return _continuous(value)
    if isinstance(value, str) or not isinstance(value, Sequence):
        raise ActionSpaceError({"": "The action space is a list of actions or a pair of ranges."})
    return _discrete(value)


# What each value of an action is called, where it may lie, and in what unit.
VALUES = {
    "steering_angle": ("steering angle", (-MAX_STEERING, MAX_STEERING), "degrees"),
    "speed": ("speed", SPEED_RANGE, "m/s"),
}
BOUNDS = {"low": "lowest", "high": "highest"}


def _discrete(value: Sequence) -> DiscreteActions:
    if not 2 <= len(value) <= 30:
        raise ActionSpaceError(
            {
                "": (
                    f"A discrete action space has 2 to 30 actions, not {len(value)}."
                    if value
                    else "There are no actions: a discrete action space has 2 to 30."
                )
            }
        )
    problems: dict[str, str] = {}
    actions: list[tuple[float, float]] = []
    seen: dict[tuple[float, float], int] = {}
    for index, action in enumerate(value):
        if not isinstance(action, Mapping):
            problems[str(index)] = f'Action {index} needs a "steering_angle" and a "speed".'
            continue
        numbers = []
        for name, (label, limits, unit) in VALUES.items():
            number, problem = _reading(
                action.get(name), f"{label.capitalize()} in action {index}", limits, unit
            )
            if problem:
                problems[f"{index}.{name}"] = problem
            numbers.append(number)
        if None in numbers:
            continue
        pair = (numbers[0], numbers[1])
        if pair in seen:
            problems[str(index)] = (
                f"Actions {seen[pair]} and {index} are the same ({pair[0]:g} degrees, "
                f"{pair[1]:g} m/s): change or remove one."
            )
        seen.setdefault(pair, index)
        actions.append(pair)
    if problems:
        raise ActionSpaceError(problems)
    return DiscreteActions(tuple(actions))


def _continuous(value: Mapping) -> ContinuousActions:
    problems: dict[str, str] = {}
    ranges = {}
    for name, (label, limits, unit) in VALUES.items():
        bounds = value.get(name)
        if not isinstance(bounds, Mapping):
            raise ActionSpaceError(
                {
                    "": (
                        'A continuous action space is {"steering_angle": {"low": -30, "high": 30}, '
                        '"speed": {"low": 1, "high": 2}}.'
                    )
                }
            )
        for bound, word in BOUNDS.items():
            number, problem = _reading(bounds.get(bound), f"The {word} {label}", limits, unit)
            if problem:
                problems[f"{name}.{bound}"] = problem
            ranges[name, bound] = number
        low, high = ranges[name, "low"], ranges[name, "high"]
        if low is not None and high is not None and low >= high:
            problems[f"{name}.high"] = (
                f"The highest {label} must be above the lowest, {low:g} {unit}."
            )
    if problems:
        raise ActionSpaceError(problems)
    return ContinuousActions(
        steering=(ranges["steering_angle", "low"], ranges["steering_angle", "high"]),
        speed=(ranges["speed", "low"], ranges["speed", "high"]),
    )


def _reading(
    value, what: str, limits: tuple[float, float], unit: str
) -> tuple[float | None, str | None]:
    """(the number, None), or (None, what is wrong with it) for a value a racer typed."""
    low, high = limits
    allowed = f"{low:g} to {high:g} {unit}"
    if value is None or (isinstance(value, str) and not value.strip()):
        return None, f"{what} is blank: enter {allowed}."
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(value, bool) or not math.isfinite(number):
        return None, f"{what} must be a number from {allowed}, not “{value}”."
    if not low <= number <= high:
        return None, f"{what} is {allowed}, not {number:g}."
    return number, None


Option = TypeVar("Option")


def choice(name: str, value, allowed: Sequence[Option]) -> Option:
    """``value``, one of ``allowed`` (a name, or None for a render mode); ``ConfigError`` else."""
    if value not in allowed:
        names = ", ".join(str(option) for option in allowed)
        raise ConfigError(f"{name} must be one of {names}, not {value!r}.")
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


def resets(value) -> int | None:
    """The resets an evaluation's episode may use; None: no limit."""
    return None if value is None else positive_int("The number of resets", value, 0, MAX_RESETS)


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
