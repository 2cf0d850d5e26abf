"""A model's training history read back from DeepRacer's ``metrics/training_metrics.json``
(docs/coming-from-deepracer.md), as an imported model's page shows it: the iterations of its
graph and table, and the totals of its training.

The file holds one row per episode, in the order they were driven: the training episodes of an
iteration (``phase: "training"``, ``trial`` counting 1, 2, ... within the iteration), then the
evaluation episodes of the policy learnt from them (``phase: "evaluation"``). Our trainer writes
it so (``jobs.trainer``), and so does DeepRacer's simulation application, whose exports read
the same way. An iteration begins at a training row that follows an evaluation, or whose trial
count starts again; a file without trial counts is cut every ``episodes_per_iteration`` rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import mean

from django.utils import timezone

from common import documents
from simulator.config import CONTROL_HZ
from training.models import Iteration, JobLogLine, TrainingJob

LAP_COMPLETE = "lap_complete"  # statuses are read in the trace's spelling: "Lap complete" too


class Unreadable(Exception):
    """The metrics cannot be read as a training history; the message says why, for the racer."""


@dataclass
class Episode:
    reward: float
    progress: float
    milliseconds: int
    status: str
    episode: int | None
    trial: int | None
    started: int | None
    ended: int | None

    @property
    def lap_time(self) -> float | None:
        """[s] when the episode completed a lap."""
        done = self.status == LAP_COMPLETE and self.progress >= 100
        return self.milliseconds / 1000 if done and self.milliseconds > 0 else None


@dataclass
class Group:
    """One iteration's rows: its training episodes and the evaluation that followed."""

    training: list[Episode] = field(default_factory=list)
    evaluation: list[Episode] = field(default_factory=list)

    def record(self, number: int) -> Iteration:
        laps = [lap for e in self.training if (lap := e.lap_time) is not None]
        return Iteration(
            number=number,
            reward=mean(e.reward for e in self.training),
            completion=mean(e.progress for e in self.training),
            evaluation_completion=(
                mean(e.progress for e in self.evaluation) if self.evaluation else None
            ),
            best_lap_time=min(laps) if laps else None,
            episodes=len(self.training),
            steps=sum(_steps(e) for e in self.training),
            wall_seconds=0.0,  # how long the update took is not in the file
            training_points=[[round(e.reward, 3), round(e.progress, 2)] for e in self.training],
            evaluation_points=[round(e.progress, 2) for e in self.evaluation],
        )


@dataclass
class History:
    iterations: list[Iteration]
    seconds: float  # [s] of training, from the first episode's start to the last one's end

    @property
    def episodes(self) -> int:
        return sum(row.episodes for row in self.iterations)

    @property
    def steps(self) -> int:
        return sum(row.steps for row in self.iterations)


def read(document: bytes, *, episodes_per_iteration: int) -> History:
    """The history in a training metrics file; ``Unreadable`` when it holds none."""
    try:
        metrics = documents.json_loads(document)["metrics"]
    except documents.Unreadable as unreadable:
        raise Unreadable(str(unreadable)) from None
    except (ValueError, KeyError, TypeError):
        raise Unreadable("it is not DeepRacer's training metrics JSON") from None
    if not isinstance(metrics, list):
        raise Unreadable("its metrics are not a list of episodes")
    groups: list[Group] = []
    for position, row in enumerate(metrics, start=1):
        if not isinstance(row, dict) or row.get("phase") not in ("training", "evaluation"):
            raise Unreadable(f"episode row {position} has no training or evaluation phase")
        episode = _episode(row, position)
        if row["phase"] == "evaluation":
            if groups:  # an evaluation before any training has no policy to belong to
                groups[-1].evaluation.append(episode)
        elif _begins_iteration(groups, episode, episodes_per_iteration):
            groups.append(Group(training=[episode]))
        else:
            groups[-1].training.append(episode)
    if not groups:
        raise Unreadable("it holds no training episode")
    return History([group.record(n) for n, group in enumerate(groups, 1)], _seconds(groups))


def _begins_iteration(groups: list[Group], episode: Episode, size: int) -> bool:
    if not groups or groups[-1].evaluation:
        return True
    previous = groups[-1].training[-1]
    if episode.trial is not None and previous.trial is not None:
        return episode.trial <= previous.trial
    return len(groups[-1].training) >= size


def _episode(row: dict, position: int) -> Episode:
    try:
        reward = float(row.get("reward_score", 0))
        progress = min(max(float(row["completion_percentage"]), 0.0), 100.0)
        milliseconds = max(int(row.get("elapsed_time_in_milliseconds", 0)), 0)
    except (KeyError, TypeError, ValueError):
        raise Unreadable(f"episode row {position} lacks a number it needs") from None
    if reward != reward or abs(reward) == float("inf"):
        raise Unreadable(f"episode row {position} has no finite reward")
    status = str(row.get("episode_status", "")).strip().lower().replace(" ", "_")
    return Episode(
        reward=reward,
        progress=progress,
        milliseconds=milliseconds,
        status=status,
        episode=_whole(row.get("episode")),
        trial=_whole(row.get("trial")),
        started=_whole(row.get("start_time")),
        ended=_whole(row.get("metric_time")),
    )


def _whole(value: object) -> int | None:
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _steps(episode: Episode) -> int:
    return round(episode.milliseconds * CONTROL_HZ / 1000)


def _seconds(groups: list[Group]) -> float:
    """[s] from the first training episode's start to the last episode's end when the file says
    when they ran; else the time the training episodes drove."""
    episodes = [e for group in groups for e in (*group.training, *group.evaluation)]
    starts = [e.started for e in episodes if e.started is not None]
    ends = [e.ended for e in episodes if e.ended is not None]
    if starts and ends and max(ends) > min(starts):
        return (max(ends) - min(starts)) / 1000
    return sum(e.milliseconds for group in groups for e in group.training) / 1000


def history_save(*, job: TrainingJob, history: History, seconds: float | None = None) -> None:
    """Give ``job`` (a finished job that never ran here) the iterations and totals of
    ``history``; ``seconds``, when the archive says it, is the training time."""
    for row in history.iterations:
        row.job = job
    Iteration.objects.bulk_create(history.iterations)
    job.iterations, job.episodes, job.steps = (
        len(history.iterations),
        history.episodes,
        history.steps,
    )
    job.training_seconds = history.seconds if seconds is None else seconds
    job.finished_at = job.clock_at = timezone.now()
    job.message = "Imported with its weights and its training history."
    job.save(
        update_fields=[
            "iterations",
            "episodes",
            "steps",
            "training_seconds",
            "finished_at",
            "clock_at",
            "message",
        ]
    )
    JobLogLine.objects.create(
        job=job,
        text=f"Imported with its training history: {job.iterations} iteration"
        f"{'s' if job.iterations != 1 else ''}, {job.episodes} episodes.",
    )


# Pitlane's own record of a training, beside DeepRacer's metrics in a virtual model's archive
# (``exports.virtual``): each iteration's figures exactly as its page shows them (the metrics
# hold one rounded row per episode, from which ``read`` can only rebuild them), and which
# iterations the best and the last checkpoints hold, for their labels.
EXACT = "pitlane-history.json"
EXACT_FORMAT = 1
_NUMBERS = ("reward", "completion", "wall_seconds")
_OPTIONAL = ("evaluation_completion", "best_lap_time", "evaluation_seconds")
_COUNTS = ("episodes", "steps")


@dataclass
class Exact:
    """What ``EXACT`` holds: the history, and the iterations of the best and last checkpoints
    (None where the weights are not an iteration's)."""

    history: History
    checkpoints: dict[str, int | None]


def exact_document(*, job: TrainingJob, checkpoints: dict[str, int | None]) -> dict:
    """``EXACT``'s document for ``job``: its iterations and ``checkpoints`` ({"best": n, ...})."""
    rows = []
    for row in job.iteration_rows.order_by("number"):
        rows.append(
            {
                "number": row.number,
                **{name: getattr(row, name) for name in _NUMBERS + _OPTIONAL},
                **{name: getattr(row, name) for name in _COUNTS},
                "time_split": row.time_split,
                "training_points": row.training_points,
                "evaluation_points": row.evaluation_points,
            }
        )
    return {"format": EXACT_FORMAT, "iterations": rows, "checkpoints": checkpoints}


def exact_read(document: bytes) -> Exact:
    """The history in ``EXACT``, every figure checked; ``Unreadable`` for anything amiss."""
    try:
        given = documents.json_loads(document)
    except documents.Unreadable as unreadable:
        raise Unreadable(str(unreadable)) from None
    except ValueError:
        raise Unreadable("it is not JSON") from None
    if not isinstance(given, dict) or given.get("format") != EXACT_FORMAT:
        raise Unreadable("it is not a format this console reads")
    rows = given.get("iterations")
    if not isinstance(rows, list) or not rows:
        raise Unreadable("it holds no iteration")
    iterations = [_exact_row(row, number) for number, row in enumerate(rows, start=1)]
    marked = given.get("checkpoints") if isinstance(given.get("checkpoints"), dict) else {}
    checkpoints = {
        which: number if _whole(number) and 1 <= number <= len(rows) else None
        for which in ("best", "last")
        for number in [marked.get(which)]
    }
    seconds = sum(row.wall_seconds for row in iterations)
    return Exact(History(iterations, seconds), checkpoints)


def _exact_row(row: object, number: int) -> Iteration:
    if not isinstance(row, dict) or row.get("number") != number:
        raise Unreadable(f"its iteration {number} is missing or out of order")
    values = {name: _finite(row.get(name), number, name) for name in _NUMBERS}
    for name in _OPTIONAL:
        values[name] = None if row.get(name) is None else _finite(row[name], number, name)
    for name in _COUNTS:
        if _whole(row.get(name)) is None or row[name] < 0:
            raise Unreadable(f"its iteration {number} has no whole number of {name}")
        values[name] = row[name]
    points = row.get("training_points", [])
    evaluation = row.get("evaluation_points", [])
    split = row.get("time_split", {})
    if not (
        isinstance(points, list)
        and isinstance(evaluation, list)
        and isinstance(split, dict)
        and all(isinstance(p, list) and len(p) == 2 for p in points)
    ):
        raise Unreadable(f"its iteration {number} has points that are not lists of numbers")
    return Iteration(
        number=number,
        **values,
        time_split={str(k): _finite(v, number, "time_split") for k, v in split.items()},
        training_points=[
            [_finite(r, number, "points"), _finite(p, number, "points")] for r, p in points
        ],
        evaluation_points=[_finite(p, number, "points") for p in evaluation],
    )


def _finite(value: object, number: int, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise Unreadable(f"its iteration {number} has no finite {name.replace('_', ' ')}")
    return value
