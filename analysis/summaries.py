"""What the analysis pages show, computed once per recorded trace and combined on request.

A trace (one training iteration, or one evaluation) is summarised when it is recorded
(``summarize``): its episodes, where the car left the track, how often each action was chosen
per track section and outcome, and an even sample of its steps for the map. A page then combines
the summaries of the iterations a racer picks (``combine_*``), so it reads kilobytes per
iteration instead of the trace's megabytes, however long the job ran.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass

import numpy as np

from analysis.traces import OUTCOMES, Steps

VERSION = 1  # of what ``summarize`` writes: summaries of another version are made again
SECTIONS = 10  # the lap cut in tenths by waypoint, for the actions per section
POINTS_PER_TRACE = 2_000  # steps of a trace kept for the map, evenly spread
POINT_COLUMNS = ("x", "y", "reward", "speed", "steer", "action", "outcome", "row")
# Histograms of the chosen steering and speed: DeepRacer's whole ranges (±30°, up to 4 m/s).
STEER_EDGES = np.linspace(-32.5, 32.5, 14)  # 13 bins centred on -30, -25, ..., 30 [deg]
SPEED_EDGES = np.linspace(0.0, 4.0, 17)  # 16 bins of 0.25 m/s
STEER_BINS, SPEED_BINS = len(STEER_EDGES) - 1, len(SPEED_EDGES) - 1


@dataclass(frozen=True)
class Summary:
    # [number, start waypoint, steps, progress %, seconds, outcome index, total reward]
    episodes: list[list]
    marks: list[list]  # [x, y, outcome index, episode number] where the car left or crashed
    # int32 counts, (outcome, section, steering bin | speed bin | action): ``action_tables``
    actions: bytes
    points: bytes  # float32, POINT_COLUMNS, one column after another
    steps: int  # driven steps (prepare rows not counted)


def summarize(steps: Steps, *, waypoints: int, actions: int | None) -> Summary:
    """``steps``' summary on a track of ``waypoints`` waypoints, for a model of ``actions``
    discrete actions (None: a continuous action space)."""
    episodes = steps.episodes()
    codes = np.array([OUTCOMES.index(e.outcome) for e in episodes], dtype=np.int64)
    lengths = np.array([e.last - e.first + 1 for e in episodes], dtype=np.int64)
    row_outcome = np.repeat(codes, lengths) if len(episodes) else np.zeros(0, np.int64)
    driven = steps.driven
    section = np.clip(steps.closest_waypoint * SECTIONS // max(waypoints - 1, 1), 0, SECTIONS - 1)
    leaving = steps.leaving()
    return Summary(
        episodes=[
            [
                e.number,
                e.start,
                e.steps,
                round(e.progress, 2),
                round(e.seconds, 3),
                int(code),
                round(e.reward, 4),
            ]
            for e, code in zip(episodes, codes, strict=True)
        ],
        marks=[
            [
                round(float(steps.x[i]), 3),
                round(float(steps.y[i]), 3),
                int(row_outcome[i]),
                int(steps.episode[i]),
            ]
            for i in leaving
        ],
        actions=_action_counts(steps, section, driven, row_outcome, actions),
        points=_points(steps, driven, row_outcome),
        steps=int(driven.sum()),
    )


def _action_counts(
    steps: Steps,
    section: np.ndarray,
    driven: np.ndarray,
    row_outcome: np.ndarray,
    actions: int | None,
) -> bytes:
    """How often each steering bin, speed bin and action was chosen, per outcome and section."""
    table = np.zeros((len(OUTCOMES), SECTIONS, STEER_BINS + SPEED_BINS + (actions or 0)), np.int32)
    rows = np.flatnonzero(driven)
    steer = np.clip(np.digitize(steps.steer[rows], STEER_EDGES) - 1, 0, STEER_BINS - 1)
    speed = np.clip(np.digitize(steps.speed[rows], SPEED_EDGES) - 1, 0, SPEED_BINS - 1)
    where = (row_outcome[rows], section[rows])
    np.add.at(table, (*where, steer), 1)
    np.add.at(table, (*where, STEER_BINS + speed), 1)
    if actions:
        chosen = steps.action[rows]
        known = (chosen >= 0) & (chosen < actions)
        kept = (where[0][known], where[1][known], STEER_BINS + SPEED_BINS + chosen[known])
        np.add.at(table, kept, 1)
    return table.tobytes()


def action_tables(data: bytes) -> np.ndarray:
    """A summary's action counts as an (outcome, section, column) array."""
    return np.frombuffer(data, dtype=np.int32).reshape(len(OUTCOMES), SECTIONS, -1)


def _points(steps: Steps, driven: np.ndarray, row_outcome: np.ndarray) -> bytes:
    rows = np.flatnonzero(driven)
    if len(rows) > POINTS_PER_TRACE:
        rows = rows[np.linspace(0, len(rows) - 1, POINTS_PER_TRACE).round().astype(np.int64)]
    columns = (
        steps.x,
        steps.y,
        steps.reward,
        steps.speed,
        steps.steer,
        steps.action,
        row_outcome,
        np.arange(len(steps)),
    )
    return np.stack([np.asarray(c)[rows] for c in columns]).astype(np.float32).tobytes()


def points_array(data: bytes) -> np.ndarray:
    """A summary's points as a (columns, n) array."""
    return np.frombuffer(data, dtype=np.float32).reshape(len(POINT_COLUMNS), -1)


# Combining summaries


def outcome_codes(chosen: list[str]) -> list[int]:
    return [OUTCOMES.index(name) for name in chosen]


def iteration_figures(episodes: list[list]) -> dict:
    """One iteration's figures from its summarised episodes: average reward and progress, the
    share of laps completed, and the best and median lap of those."""
    if not episodes:
        return {
            "episodes": 0,
            "reward": None,
            "progress": None,
            "completion": None,
            "best_lap": None,
            "median_lap": None,
        }
    laps = [e[4] for e in episodes if e[5] == 0]
    return {
        "episodes": len(episodes),
        "reward": statistics.fmean(e[6] for e in episodes),
        "progress": statistics.fmean(e[3] for e in episodes),
        "completion": 100.0 * len(laps) / len(episodes),
        "best_lap": min(laps) if laps else None,
        "median_lap": statistics.median(laps) if laps else None,
    }


def combine_actions(blobs: list[bytes], outcomes: list[str]) -> dict[str, list[list[int]]]:
    """The action counts per section of ``blobs`` (summaries' ``actions``) over ``outcomes``:
    ``steer`` and ``speed`` (SECTIONS x bins), and ``actions`` (SECTIONS x actions, empty for a
    continuous action space)."""
    codes = outcome_codes(outcomes)
    total = None
    for data in blobs:
        counts = action_tables(data)[codes].sum(axis=0, dtype=np.int64)
        total = counts if total is None or total.shape != counts.shape else total + counts
    if total is None:
        total = np.zeros((SECTIONS, STEER_BINS + SPEED_BINS), np.int64)
    return {
        "steer": total[:, :STEER_BINS].tolist(),
        "speed": total[:, STEER_BINS : STEER_BINS + SPEED_BINS].tolist(),
        "actions": total[:, STEER_BINS + SPEED_BINS :].tolist(),
    }


def combine_points(
    blobs: list[tuple[int, bytes]],
    outcomes: list[str],
    limit: int,
    *,
    extra: dict[int, np.ndarray] | None = None,
) -> np.ndarray:
    """The points of ``blobs`` ((iteration, points) pairs) whose episode ended in one of
    ``outcomes``, at most ``limit`` of them evenly spread, as a float32 array of POINT_COLUMNS,
    then the iteration, then (with ``extra``: a value per point of some iterations) that value,
    NaN where an iteration has none."""
    codes = outcome_codes(outcomes)
    rows = len(POINT_COLUMNS) + 1 + (extra is not None)
    parts = []
    for iteration, data in blobs:
        points = points_array(data)
        columns = [points, np.full((1, points.shape[1]), iteration, np.float32)]
        if extra is not None:
            values = extra.get(iteration)
            if values is None or len(values) != points.shape[1]:
                values = np.full(points.shape[1], np.nan, np.float32)
            columns.append(np.asarray(values, np.float32)[None, :])
        keep = np.isin(points[POINT_COLUMNS.index("outcome")], codes)
        parts.append(np.vstack(columns)[:, keep])
    if not parts:
        return np.zeros((rows, 0), dtype=np.float32)
    every = np.hstack(parts)
    if every.shape[1] > limit:
        every = every[:, np.linspace(0, every.shape[1] - 1, limit).round().astype(np.int64)]
    return np.ascontiguousarray(every, dtype=np.float32)
