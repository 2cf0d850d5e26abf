"""A race submission's score, from its laps (pure functions; no Django).

Lower is better. Lap times are simulated time and already include the off-track and crash
penalties, so scoring adds nothing to them. A submission qualifies only when it drove ``laps``
complete laps one after another (a lap counts when the car finished it within the event's
limits); its score then depends on the event's ranking method:

- ``FIRST_CONSECUTIVE`` (the league's rule): the average of the *first* such run of laps, even
  when a later run was faster;
- ``BEST_CONSECUTIVE``: the best average over every run of ``laps`` consecutive complete laps;
- ``BEST_LAP``: the fastest complete lap;
- ``TOTAL_TIME``: the time from the start until the first run was done, every lap before it
  (complete or not) included.

Averages are rounded to the millisecond, halves up.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

FIRST_CONSECUTIVE = "FIRST_CONSECUTIVE"
BEST_CONSECUTIVE = "BEST_CONSECUTIVE"
BEST_LAP = "BEST_LAP"
TOTAL_TIME = "TOTAL_TIME"
METHODS = (FIRST_CONSECUTIVE, BEST_CONSECUTIVE, BEST_LAP, TOTAL_TIME)


@dataclass(frozen=True)
class Lap:
    time_ms: int  # penalties included
    counted: bool  # the car finished the lap within the event's limits


def windows(laps: Sequence[Lap], size: int) -> list[int]:
    """Where each run of ``size`` consecutive counted laps starts (index of its first lap)."""
    starts, run = [], 0
    for index, lap in enumerate(laps):
        run = run + 1 if lap.counted else 0
        if run >= size:
            starts.append(index - size + 1)
    return starts


def average_ms(laps: Sequence[Lap]) -> int:
    total = sum(lap.time_ms for lap in laps)
    return (2 * total + len(laps)) // (2 * len(laps))


def score(laps: Sequence[Lap], *, method: str, size: int) -> int | None:
    """The submission's score in milliseconds, or None when it did not qualify."""
    if method not in METHODS:
        raise ValueError(f"unknown ranking method {method!r}")
    if size < 1:
        raise ValueError("a qualifying run is at least one lap")
    starts = windows(laps, size)
    if not starts:
        return None
    if method == FIRST_CONSECUTIVE:
        return average_ms(laps[starts[0] : starts[0] + size])
    if method == BEST_CONSECUTIVE:
        return min(average_ms(laps[start : start + size]) for start in starts)
    if method == BEST_LAP:
        return min(lap.time_ms for lap in laps if lap.counted)
    return sum(lap.time_ms for lap in laps[: starts[0] + size])


def counted_in_a_row(laps: Sequence[Lap]) -> int:
    """The most counted laps one after another (what a run lacked when it did not qualify)."""
    most = run = 0
    for lap in laps:
        run = run + 1 if lap.counted else 0
        most = max(most, run)
    return most


def far_below(laps: Sequence[Lap], *, share: float = 0.65) -> list[bool]:
    """For each lap, whether it is under ``share`` of the median of the run's other counted laps:
    a lap that short is more likely a double press or a cut corner than a fast lap. A lap with no
    other counted lap to compare with is not."""
    flags = []
    for index, lap in enumerate(laps):
        others = sorted(
            other.time_ms for i, other in enumerate(laps) if i != index and other.counted
        )
        if not others:
            flags.append(False)
            continue
        middle = len(others) // 2
        median = others[middle] if len(others) % 2 else (others[middle - 1] + others[middle]) / 2
        flags.append(lap.time_ms < share * median)
    return flags
