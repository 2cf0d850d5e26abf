"""The one reader of recorded simulation traces (``simulator.trace``'s CSV, DeepRacer's format):
a document into columns, its episodes, and the places the car left the track.

Every page and task of analysis reads traces through here. The rules are deepracer-utils' (the
community's notebooks): an episode's steps are its largest ``steps``, its time the sum of its
``tstamp`` differences (deepracer_utils/logs/log_utils.py:349, simulation_agg), its start the
closest waypoint of its first row (``start_at``).
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

import numpy as np

from simulator.params import Recorded
from simulator.trace import FIELDS

# An episode's outcome, as the analysis filters it: the three a racer asks about, then the rest
# (reversed, immobilized, time up, in progress).
OUTCOMES = ("lap_complete", "off_track", "crashed", "other")
OUTCOME_LABELS = {
    "lap_complete": "Lap complete",
    "off_track": "Off track",
    "crashed": "Crashed",
    "other": "Other (reversed, immobilized, time up)",
}
LEAVING = ("off_track", "crashed")  # the statuses marked on the track where they happen
READ = (
    "episode",
    "steps",
    "X",
    "Y",
    "yaw",
    "steer",
    "throttle",
    "action",
    "reward",
    "all_wheels_on_track",
    "progress",
    "closest_waypoint",
    "tstamp",
    "episode_status",
)
MAX_ROWS = 2_000_000  # a trace longer than this is not read (a 10-hour job writes ~10,000/file)


class Unreadable(ValueError):
    """The document is not a simulation trace; the message says why, in a racer's words."""


def outcome(status: str) -> str:
    """The outcome group of an episode that ended with ``status``."""
    return status if status in OUTCOMES else "other"


@dataclass(frozen=True)
class Steps:
    """A trace's rows as columns, each an array with one entry per row, prepare rows included."""

    episode: np.ndarray  # int64
    steps: np.ndarray  # int64
    x: np.ndarray  # [m]
    y: np.ndarray  # [m]
    yaw: np.ndarray  # [deg]
    steer: np.ndarray  # [deg]
    speed: np.ndarray  # [m/s] the commanded speed (the trace's throttle)
    action: np.ndarray  # int64: the action's index; -1 for a continuous action
    reward: np.ndarray
    all_wheels_on_track: np.ndarray  # bool
    progress: np.ndarray  # [%]
    closest_waypoint: np.ndarray  # int64
    tstamp: np.ndarray  # [s]
    status: np.ndarray  # str

    def __len__(self) -> int:
        return len(self.episode)

    @property
    def driven(self) -> np.ndarray:
        """Rows of steps the car drove: not the episode's prepare row."""
        return self.status != "prepare"

    def episodes(self) -> list[Episode]:
        """The trace's episodes in the order they were recorded."""
        if not len(self):
            return []
        cuts = np.flatnonzero(np.diff(self.episode) != 0) + 1
        starts = np.concatenate([[0], cuts])
        ends = np.concatenate([cuts, [len(self)]])
        totals = np.add.reduceat(self.reward, starts)
        return [
            Episode(
                number=int(self.episode[a]),
                first=int(a),
                last=int(b - 1),
                start=int(self.closest_waypoint[a]),
                steps=int(self.steps[a:b].max()),
                progress=float(self.progress[b - 1]),
                seconds=float(self.tstamp[b - 1] - self.tstamp[a]),
                status=str(self.status[b - 1]),
                reward=float(total),
            )
            for a, b, total in zip(starts, ends, totals, strict=True)
        ]

    def recorded(self, rows: slice | np.ndarray) -> Recorded:
        """What ``simulator.params.replayed`` reads of ``rows`` (a slice or row indices)."""
        return Recorded(
            x=self.x[rows],
            y=self.y[rows],
            yaw=self.yaw[rows],
            steer=self.steer[rows],
            speed=self.speed[rows],
            progress=self.progress[rows],
            steps=self.steps[rows],
            all_wheels_on_track=self.all_wheels_on_track[rows],
            status=self.status[rows],
            tstamp=self.tstamp[rows],
        )

    def leaving(self) -> np.ndarray:
        """The rows where the car left the track or crashed: the first row of each incident."""
        leaving = np.isin(self.status, LEAVING)
        first = leaving.copy()
        first[1:] &= ~leaving[:-1] | (np.diff(self.episode) != 0)
        return np.flatnonzero(first)


@dataclass(frozen=True)
class Episode:
    number: int
    first: int  # its rows in the trace: first..last
    last: int
    start: int  # the closest waypoint where it began
    steps: int
    progress: float  # [%]
    seconds: float  # penalties included
    status: str  # how it ended, in the trace's spelling
    reward: float  # the sum over its steps

    @property
    def outcome(self) -> str:
        return outcome(self.status)

    @property
    def lap_seconds(self) -> float | None:
        return self.seconds if self.status == "lap_complete" else None


def read(document: bytes | str) -> Steps:
    """A simulation trace's CSV; ``Unreadable`` when it is none."""
    text = document.decode("utf-8", errors="replace") if isinstance(document, bytes) else document
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        raise Unreadable("The simulation trace is empty.")
    missing = [name for name in READ if name not in header]
    if missing:
        raise Unreadable(
            "This is not a simulation trace: it has no column "
            + ", ".join(missing[:3])
            + (f" (DeepRacer's trace has {len(FIELDS)} columns)." if len(missing) > 3 else ".")
        )
    where = [header.index(name) for name in READ]
    rows = []
    for number, row in enumerate(reader, start=2):
        if len(rows) >= MAX_ROWS:
            raise Unreadable(f"The simulation trace has more than {MAX_ROWS:,} rows.")
        try:
            rows.append([row[i] for i in where])
        except IndexError:
            raise Unreadable(f"Line {number} of the simulation trace is cut short.") from None
    columns = list(zip(*rows, strict=True)) if rows else [()] * len(READ)
    try:
        return _steps(dict(zip(READ, columns, strict=True)))
    except ValueError as error:
        raise Unreadable(
            f"The simulation trace holds a value that is not a number ({error})."
        ) from None


def _steps(column: dict[str, tuple[str, ...]]) -> Steps:
    def floats(name: str) -> np.ndarray:
        return np.asarray(column[name], dtype=np.float64)

    actions = column["action"]
    continuous = bool(actions) and actions[0].startswith("[")
    return Steps(
        episode=np.asarray(column["episode"], dtype=np.int64),
        steps=floats("steps").astype(np.int64),
        x=floats("X"),
        y=floats("Y"),
        yaw=floats("yaw"),
        steer=floats("steer"),
        speed=floats("throttle"),
        action=np.full(len(actions), -1, np.int64)
        if continuous
        else np.asarray(actions, dtype=np.int64),
        reward=floats("reward"),
        all_wheels_on_track=np.asarray(column["all_wheels_on_track"]) == "True",
        progress=floats("progress"),
        closest_waypoint=np.asarray(column["closest_waypoint"], dtype=np.int64),
        tstamp=floats("tstamp"),
        status=np.asarray(column["episode_status"], dtype=str),
    )
