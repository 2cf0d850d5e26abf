"""A complete lap against the racing line, sector by sector (issue 59): where the lap loses time.

The lap is cut in ``SECTORS`` equal shares of its progress: DeepRacer's progress, the share of
the track's centre line covered since the episode's start. The recorded steps' progress says
between which two rows the car crossed each cut, and the centre line where on the path between
them; the racing line's points are projected onto the same centre line, so that the line and the
car are timed between the same gates across the track (the line cuts the corners: a tenth of its
own length ends somewhere else). The line is driven from where the lap
began, from rest when the lap's episode began at rest (``simulator.racing_line.racing_line``'s
standing start: v² = 2 a s until the flying lap's speed), else at its flying lap's speeds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simulator.racing_line import RacingLine, from_rest
from simulator.tracks import Track

SECTORS = 10
# [m] between the points whose progress is read off the centre line where a gate is crossed:
# progress on a polyline is not linear between two rows a quarter of a metre apart where it
# turns at a waypoint (up to a hundredth of a second off at a gate), and jumps inside a bend.
FINE = 0.002
ROUND = 3  # decimals sent to the browser: a millisecond, a millimetre, a mm/s


@dataclass(frozen=True)
class Lap:
    """A lap as it went: at each of its ``points`` (k, 2) [m] the share of the lap done
    (``fractions``, 0 at its start, 1 once round), the ``times`` [s] and the ``distances`` [m]
    driven since its start."""

    fractions: np.ndarray
    times: np.ndarray
    distances: np.ndarray
    points: np.ndarray


def recorded_lap(*, progress: np.ndarray, tstamp: np.ndarray, x: np.ndarray, y: np.ndarray) -> Lap:
    """A recorded episode's lap from its steps (its prepare row first): ``progress`` [%] and
    ``tstamp`` [s] as the trace holds them."""
    points = np.column_stack([x, y]).astype(np.float64)
    steps = np.hypot(*np.diff(points, axis=0).T)
    times = np.asarray(tstamp, dtype=np.float64)
    return Lap(
        fractions=np.asarray(progress, dtype=np.float64) / 100,
        times=times - times[0],
        distances=np.concatenate([[0.0], np.cumsum(steps)]),
        points=points,
    )


def line_lap(
    line: RacingLine, track: Track, *, start: float, standing: bool, accelerating: float
) -> Lap:
    """``line`` driven once round ``track`` from its point nearest ``start`` (a share of the
    centre line from the start line), from rest when ``standing`` (gaining at most
    ``accelerating`` [m/s²]) and back to its flying speed there, as ``racing_line`` times a
    race's first lap."""
    ahead = (track.project_points(line.points).distance / track.length - start) % 1.0
    first = int(np.argmin(np.minimum(ahead, 1.0 - ahead)))
    order = np.roll(np.arange(len(line.points)), -first)
    points = np.vstack([line.points[order], line.points[order[:1]]])
    # Each point's share of the lap past the first, unwrapped round the loop; a point that
    # projects a little behind the one before (inside a tight bend) does not go back.
    moved = (np.diff(ahead[order]) + 0.5) % 1.0 - 0.5
    fractions = np.concatenate([[0.0], np.maximum.accumulate(np.cumsum(moved)), [1.0]])
    steps = np.hypot(*np.diff(points, axis=0).T)
    distances = np.concatenate([[0.0], np.cumsum(steps)])
    speeds = np.append(line.speeds[order], line.speeds[order[0]])
    if standing:
        speeds[:-1] = from_rest(speeds[:-1], distances[:-1], accelerating)
    times = np.concatenate([[0.0], np.cumsum(steps / ((speeds[:-1] + speeds[1:]) / 2))])
    return Lap(np.minimum(fractions, 1.0), times, distances, points)


def sector_table(line: Lap, lap: Lap, track: Track, sectors: int = SECTORS) -> dict:
    """Each sector's time on the racing line and on ``lap`` round ``track``, the gap, and the
    mean speeds (the distance driven in it over its time); ``worst``: the sector that loses
    most time, None when none loses any, with ``worst_path``: the line's points there, for
    the map."""
    cuts = np.linspace(0.0, 1.0, sectors + 1)
    line_times, line_distances = (np.diff(c) for c in _crossings(line, track, cuts))
    lap_times, lap_distances = (np.diff(c) for c in _crossings(lap, track, cuts))
    line_speeds, lap_speeds = _speeds(line_distances, line_times), _speeds(lap_distances, lap_times)
    gaps = lap_times - line_times
    worst = int(np.argmax(gaps)) if gaps.max() > 0 else None
    rows = [
        {
            "sector": k + 1,
            "from": round(100 * cuts[k]),
            "to": round(100 * cuts[k + 1]),
            "line": round(float(line_times[k]), ROUND),
            "lap": round(float(lap_times[k]), ROUND),
            "gap": round(float(gaps[k]), ROUND),
            "line_speed": line_speeds[k],
            "lap_speed": lap_speeds[k],
        }
        for k in range(sectors)
    ]
    worst_path = []
    if worst is not None:
        inside = (line.fractions >= cuts[worst]) & (line.fractions <= cuts[worst + 1])
        worst_path = np.round(line.points[inside], ROUND).tolist()
    return {
        "rows": rows,
        "line_total": round(float(line_times.sum()), ROUND),
        "lap_total": round(float(lap_times.sum()), ROUND),
        "gap_total": round(float(gaps.sum()), ROUND),
        "worst": worst,
        "worst_path": worst_path,
    }


def _crossings(lap: Lap, track: Track, cuts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The times [s] and distances [m] at which ``lap`` first reaches each cut, a share of the
    lap (``_share_at``): the first cut is the lap's start; the last, where it first reaches 1
    (a recorded lap's last row, whose time is its episode's; the line's first point again)."""
    reached = np.maximum.accumulate(lap.fractions)  # rolling back, a gate is not crossed again
    after = np.clip(np.searchsorted(reached, cuts, side="left"), 1, len(reached) - 1)
    before = after - 1
    shares = np.zeros(len(cuts))
    shares[-1] = 1.0
    for k in range(1, len(cuts) - 1):
        low, high = reached[before[k]], reached[after[k]]
        ends = lap.points[before[k]], lap.points[after[k]]
        shares[k] = _share_at(track, *ends, low, high, float(cuts[k]))
    times = lap.times[before] + shares * (lap.times[after] - lap.times[before])
    distances = lap.distances[before] + shares * (lap.distances[after] - lap.distances[before])
    return times, distances


def _share_at(
    track: Track, start: np.ndarray, end: np.ndarray, low: float, high: float, cut: float
) -> float:
    """How far (0 to 1) along the straight path from ``start`` to ``end``, whose progress goes
    from ``low`` to ``high``, it first reaches ``cut``: its progress read off ``track``'s
    centre line every ``FINE`` metres, never behind ``low`` nor past ``high`` (so a recorded
    lap's progress stays what it was at each row)."""
    parts = max(int(np.ceil(np.hypot(*(end - start)) / FINE)), 1)
    share = np.linspace(0.0, 1.0, parts + 1)
    along = track.project_points(start + share[:, None] * (end - start)).distance
    half = track.length / 2
    moved = ((along - along[0] + half) % track.length - half) / track.length
    fractions = np.maximum.accumulate(np.clip(low + moved, low, high))
    fractions[-1] = high
    after = int(np.clip(np.searchsorted(fractions, cut, side="left"), 1, parts))
    below, above = fractions[after - 1], fractions[after]
    within = min(max((cut - below) / (above - below), 0.0), 1.0) if above > below else 0.0
    return float(share[after - 1] + within * (share[after] - share[after - 1]))


def _speeds(distances: np.ndarray, times: np.ndarray) -> list[float | None]:
    return [
        round(float(d / t), ROUND) if t > 0 else None for d, t in zip(distances, times, strict=True)
    ]
