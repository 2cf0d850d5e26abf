"""Reward functions: the checks every returned reward passes, and the default function."""

from __future__ import annotations

import math

MAX_REWARD = 1e5


class RewardError(ValueError):
    """The reward function returned something that is not a usable reward."""


def checked_reward(value: object) -> float:
    """``value`` as a float, if it is a finite real number within ±1e5 (an int, a bool or a numpy
    scalar is accepted); otherwise ``RewardError`` saying what came back."""
    if isinstance(value, complex) or not hasattr(value, "__float__") or isinstance(value, str):
        raise RewardError(
            f"The reward function returned {type(value).__name__} {_repr(value)}, not a number."
        )
    try:
        reward = float(value)
    except (TypeError, ValueError, OverflowError):
        raise RewardError(
            f"The reward function returned {type(value).__name__} {_repr(value)}, not a number."
        ) from None
    if not math.isfinite(reward) or abs(reward) > MAX_REWARD:
        raise RewardError(
            f"The reward function returned {_repr(value)}; a reward is a finite number "
            f"within ±{MAX_REWARD:g}."
        )
    return reward


def _repr(value: object) -> str:
    """``value`` as Python writes it, for a racer's message: 60 characters at most."""
    try:
        text = repr(value)
    except Exception:  # a value whose repr fails is still reported
        text = "(unprintable)"
    return text if len(text) <= 60 else text[:57] + "..."


def follow_centre_line(params: dict) -> float:
    """DeepRacer's first example: the closer to the centre line, the higher the reward."""
    track_width = params["track_width"]
    distance_from_center = params["distance_from_center"]
    if distance_from_center <= 0.1 * track_width:
        reward = 1.0
    elif distance_from_center <= 0.25 * track_width:
        reward = 0.5
    elif distance_from_center <= 0.5 * track_width:
        reward = 0.1
    else:
        reward = 1e-3  # likely crashed or close to off track
    return float(reward)
