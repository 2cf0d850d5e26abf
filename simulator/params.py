"""DeepRacer's reward params: the rules the environment and the replay of a recorded trace share.

The environment (``env``) builds the params of the car it simulates. ``replayed`` builds them
again from a simulation trace alone, for scoring recorded driving with another reward function:
what the trace does not record (the objects of an object-avoidance or head-to-bot race) comes
as DeepRacer gives it when there are no objects. This module imports no simulator engine.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterator, Sequence
from typing import NamedTuple

import numpy as np

from simulator.tracks import Track


def object_param_defaults() -> dict:
    """The object keys as DeepRacer gives them when there are no objects: every race has them.
    simapp bundle/markov/agent_ctrl/constants.py:110-136, track_geom/track_data.py:380-381
    (01f5f01)."""
    return {
        "closest_objects": [0, 0],
        "objects_location": [],
        "objects_distance": [],
        "objects_distance_from_center": [],
        "objects_heading": [],
        "objects_left_of_center": [],
        "objects_speed": [],
        "object_in_camera": False,
    }


def prev_next(distances: Sequence[float], x: float) -> tuple[int, int]:
    """The indices before and after ``x`` in the ascending ``distances``: after is the first
    greater one (so ``x`` equal to entry i gives (i, i + 1)), wrapping past either end. simapp
    bundle/markov/track_geom/utils.py:140-147 find_prev_next (01f5f01)."""
    after = bisect.bisect_right(distances, x)
    before = after - 1 if after > 0 else len(distances) - 1
    return before, after if after < len(distances) else 0


def waypoint_distances(track: Track) -> list[float]:
    """Each waypoint's distance along the centre line, the last one the full lap: simapp
    track_geom/track_data.py:47-48 (01f5f01) normalises by the length, which orders alike.
    Computed as Track.project_points computes distances, so a car exactly on a waypoint
    projects to exactly that waypoint's distance."""
    steps = np.diff(track.centre, axis=0)
    cumulative = np.concatenate(
        [[0.0], np.cumsum(np.sqrt(np.maximum((steps**2).sum(axis=1), 1e-12)))]
    )
    return [*cumulative[:-1].tolist(), math.inf]


def heading(yaw: float) -> float:
    """DeepRacer's heading [deg] in (-180, 180] from a yaw in degrees."""
    return yaw if yaw > -180.0 else 180.0


class Recorded(NamedTuple):
    """The columns of a recorded trace that ``replayed`` reads, one entry per step."""

    x: Sequence[float]
    y: Sequence[float]
    yaw: Sequence[float]  # [deg]
    steer: Sequence[float]  # [deg]
    speed: Sequence[float]  # [m/s] commanded: the trace's throttle
    progress: Sequence[float]
    steps: Sequence[float]
    all_wheels_on_track: Sequence[bool]
    status: Sequence[str]
    tstamp: Sequence[float]


def replayed(track: Track, recorded: Recorded) -> Iterator[dict]:
    """The reward params of each recorded step, as the environment gave them when it drove
    there (``env.DeepRacerEnv._params``), without ``waypoints``: the caller sends those once."""
    points = np.column_stack([np.asarray(recorded.x), np.asarray(recorded.y)])
    if not len(points):
        return
    projection = track.project_points(points)
    distances = waypoint_distances(track)
    common = {"is_reversed": track.reversed, "track_length": track.length}
    for i in range(len(points)):
        distance = float(projection.distance[i])
        status = recorded.status[i]
        yield {
            "all_wheels_on_track": bool(recorded.all_wheels_on_track[i]),
            "x": float(points[i, 0]),
            "y": float(points[i, 1]),
            "heading": heading(float(recorded.yaw[i])),
            "distance_from_center": float(projection.offset[i]),
            "is_left_of_center": bool(projection.is_left[i]),
            "is_offtrack": status == "off_track",
            "is_crashed": status == "crashed",
            "progress": float(recorded.progress[i]),
            "steps": float(recorded.steps[i]),
            "speed": float(recorded.speed[i]),
            "steering_angle": float(recorded.steer[i]),
            "track_width": float(projection.width[i]),
            "closest_waypoints": list(prev_next(distances, distance)),
            "projection_distance": distance,
            "sim_time": float(recorded.tstamp[i]),
            **common,
            **object_param_defaults(),
        }
