"""Reward functions the simulator uses when a racer gives none."""

from __future__ import annotations


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
