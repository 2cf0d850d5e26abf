"""DeepRacer's simulation trace: one row per step, as log lines and per-iteration CSV files.

The 19 fields, in DeepRacer's order, are what deepracer-utils and Log Guru read. A continuous
action is written ``[steer speed]``; booleans as True/False, as DeepRacer writes them. As in
DeepRacer, an episode's first row is its ``prepare`` row (steps 1.0, reward 0, done False), and
``tstamp`` is the simulation clock, which runs on from episode to episode: deepracer-utils times an
episode by summing tstamp differences, zeroing the one that arrives at a prepare row (simapp
bundle/markov/agent_ctrl/rollout_agent_ctrl.py:800,1079; metrics/constants.py:48-68, 01f5f01).
"""

from __future__ import annotations

import csv
import io
import time
from pathlib import Path
from typing import NamedTuple, TextIO

LOG_PREFIX = "SIM_TRACE_LOG:"


class SimTraceRow(NamedTuple):
    episode: int
    steps: float  # 1.0 on the episode's prepare row, as DeepRacer writes it
    X: float
    Y: float
    yaw: float  # [deg]
    steer: float  # [deg]
    throttle: float  # [m/s]
    action: int | str  # index, or "[steer speed]" for a continuous action
    reward: float
    done: bool
    all_wheels_on_track: bool
    progress: float
    closest_waypoint: int
    track_len: float
    tstamp: float  # [s] the worker's simulation clock: never runs backwards
    episode_status: str
    pause_duration: float  # [s]
    obstacle_crash_counter: int
    wall_clock: float | None  # [s] since the epoch; None: stamped when the row is written


FIELDS = SimTraceRow._fields


def _cells(row: SimTraceRow, *, log: bool = False) -> list[str]:
    """The row's fields as text. The CSV writes steps as a float (``1.0``), as simapp's
    write_simtrace_to_local_file does with str(); the log line as an integer, as its
    ``SIM_TRACE_LOG`` format's ``%d`` does (simapp metrics/s3_metrics.py:72,76-88, 01f5f01)."""
    wall_clock = time.time() if row.wall_clock is None else row.wall_clock
    return [
        str(row.episode),
        str(int(row.steps)) if log else str(float(row.steps)),
        f"{row.X:.4f}",
        f"{row.Y:.4f}",
        f"{row.yaw:.4f}",
        f"{row.steer:.2f}",
        f"{row.throttle:.2f}",
        str(row.action),
        f"{row.reward:.4f}",
        str(row.done),
        str(row.all_wheels_on_track),
        f"{row.progress:.4f}",
        str(row.closest_waypoint),
        f"{row.track_len:.2f}",
        f"{row.tstamp:.3f}",
        row.episode_status,
        f"{row.pause_duration:.3f}",
        str(row.obstacle_crash_counter),
        f"{wall_clock:.3f}",
    ]


def log_line(row: SimTraceRow) -> str:
    """``SIM_TRACE_LOG:`` followed by the 19 fields, comma-separated."""
    return LOG_PREFIX + ",".join(_cells(row, log=True))


class TraceWriter:
    """Writes rows as CSV with DeepRacer's header, to ``<directory>/<iteration>-iteration.csv``
    (``training-simtrace/`` during training, ``evaluation-simtrace/0-iteration.csv`` after)."""

    def __init__(self, file: TextIO) -> None:
        self._file = file
        self._writer = csv.writer(file, lineterminator="\n")
        self._writer.writerow(FIELDS)

    @classmethod
    def for_iteration(cls, directory: Path, iteration: int) -> TraceWriter:
        directory.mkdir(parents=True, exist_ok=True)
        return cls(open(directory / f"{iteration}-iteration.csv", "w", newline=""))

    def write(self, row: SimTraceRow) -> None:
        self._writer.writerow(_cells(row))

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> TraceWriter:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


def to_csv(rows: list[SimTraceRow]) -> str:
    """Rows as one CSV document with the header: for storage, downloads and tests."""
    buffer = io.StringIO()
    writer = TraceWriter(buffer)
    for row in rows:
        writer.write(row)
    return buffer.getvalue()
