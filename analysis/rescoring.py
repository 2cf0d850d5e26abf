"""A re-scoring, run by a simulation worker: the racer's other reward function, in the sandbox,
over the recorded steps of the iterations they picked, each given the reward params it was given
when it was driven (``simulator.params.replayed``)."""

from __future__ import annotations

import logging
import time

import numpy as np
from celery.exceptions import SoftTimeLimitExceeded
from django.utils import timezone

from analysis import lifecycle, selectors, summaries, traces
from analysis.models import Rescoring
from analysis.records import Source
from sandbox import Sandbox, SandboxFailure, SandboxUnavailable, verified
from simulator.params import replayed

logger = logging.getLogger(__name__)

BATCH = 500  # steps scored per request to the sandbox
CALL_TIMEOUT = 1.0  # [s] per call of the reward function, as in training
LOG_LINES = 50  # of what the reward function printed, kept for the page
_R = Rescoring.Status


class Failed(Exception):
    """The re-scoring cannot finish; the message says why, in the racer's words."""


def run_next() -> None:
    """Run the queued re-scoring whose turn it is (``selectors.rescorings_in_turn``: racers take
    turns), if any is left. Each re-scoring asked for queues one task, and each task runs the
    next in turn rather than its own: one racer's line cannot hold another racer's for more than
    one re-scoring. A task that finds none waiting (a redelivery) does nothing."""
    for pk in selectors.rescorings_in_turn():
        if run(pk):
            return


def run(rescoring_id: int) -> bool:
    """Run the re-scoring ``rescoring_id`` if it still waits; whether this call took it up."""
    rescoring = (
        Rescoring.objects.select_related("job__model__track", "evaluation__model", "evaluation")
        .filter(pk=rescoring_id)
        .first()
    )
    if rescoring is None or not lifecycle.RESCORING.move(
        rescoring, _R.RUNNING, only_from={_R.QUEUED}, started_at=timezone.now()
    ):
        return False  # deleted with its model, or taken up by another worker
    source = (
        Source.of_job(rescoring.job)
        if rescoring.job
        else Source.of_evaluation(rescoring.evaluation)
    )
    try:
        verified()  # SandboxUnavailable where racers' code cannot be held safely
        with Sandbox(call_timeout=CALL_TIMEOUT) as sandbox:
            result = _score(rescoring, source, sandbox)
            lines, _ = sandbox.take_logs()
    except Failed as failure:
        _fail(rescoring, str(failure))
    except SandboxUnavailable as error:
        _fail(rescoring, f"Re-scoring cannot run on this worker: {error}")
    except SoftTimeLimitExceeded:
        _fail(rescoring, "The re-scoring took too long; score fewer iterations.")
    except Exception:
        logger.exception("Re-scoring %s failed", rescoring_id)
        _fail(rescoring, "The re-scoring failed on the worker; try again.")
    else:
        lifecycle.RESCORING.move(
            rescoring, _R.DONE, finished_at=timezone.now(), log=lines[:LOG_LINES], **result
        )
    return True


def _fail(rescoring: Rescoring, why: str) -> None:
    lifecycle.RESCORING.move(rescoring, _R.FAILED, finished_at=timezone.now(), failure=why[:2000])


def _score(rescoring: Rescoring, source: Source, sandbox: Sandbox) -> dict:
    try:
        sandbox.load(rescoring.reward_function)
    except SandboxFailure as failure:
        raise Failed(f"The reward function did not load: {failure}") from None
    track = source.track
    waypoints = [list(point) for point in track.waypoints]
    kept = dict(
        source.summaries()
        .filter(iteration__range=(rescoring.first, rescoring.last))
        .values_list("iteration", "points")
    )
    episodes: dict[str, list] = {}
    points, counts, done = [], {}, 0
    for iteration in sorted(kept):
        try:
            steps = source.read(iteration)
        except traces.Unreadable as error:
            raise Failed(f"Iteration {iteration}: {error}") from None
        new = _rewards(sandbox, track, waypoints, steps, iteration, done, rescoring)
        done += int(steps.driven.sum())
        episodes[str(iteration)] = [
            [e.number, round(float(new[e.first : e.last + 1].sum()), 4)] for e in steps.episodes()
        ]
        rows = summaries.points_array(bytes(kept[iteration]))[summaries.POINT_COLUMNS.index("row")]
        points.append(new[np.clip(rows.astype(np.int64), 0, len(new) - 1)])
        counts[str(iteration)] = len(rows)
    data = np.concatenate(points).astype(np.float32).tobytes() if points else b""
    return {"episodes": episodes, "points": data, "point_counts": counts, "steps": done}


def _rewards(sandbox, track, waypoints, steps, iteration, done, rescoring) -> np.ndarray:
    """The new reward of each row of ``steps`` (0 on prepare rows, as DeepRacer never calls the
    reward function there)."""
    driven = np.flatnonzero(steps.driven)
    recorded = steps.recorded(driven)
    params = list(replayed(track, recorded))
    new = np.zeros(len(steps), dtype=np.float64)
    last_told = time.monotonic()
    for start in range(0, len(params), BATCH):
        try:
            values = sandbox.rescore(waypoints, params[start : start + BATCH])
        except SandboxFailure as failure:
            row = driven[start + failure.step] if failure.step is not None else driven[start]
            where = f"Iteration {iteration}, episode {steps.episode[row]}, step {steps.steps[row]}"
            line = f", line {failure.line}" if failure.line is not None else ""
            raise Failed(f"{where}{line}: {failure.message}") from None
        new[driven[start : start + len(values)]] = values
        if time.monotonic() - last_told > 1.0:  # the page shows how far it is
            Rescoring.objects.filter(pk=rescoring.pk).update(steps=done + start + len(values))
            last_told = time.monotonic()
    return new
