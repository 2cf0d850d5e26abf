"""What the league tells the pages that watch it, over the ``event_<id>`` channel group.

A leaderboard page listens to its event's group; when a submission is scored, disqualified or
removed, it hears a ``leaderboard`` message and fetches its table again. The racer's own
submission page hears its ``submission`` messages (status, then the score). A physical event's
timekeeper and broadcast pages hear ``timing``: the car on the track, its laps, and when the lap
on track started (``racing.timing``); the broadcast hears ``winner`` when the organiser shows it.
"""

from __future__ import annotations

import time

from django.db import transaction

from accounts.selectors import racer_name
from common.formatting import laptime
from racing import scoring
from racing.models import Event, LiveEntry, LiveSession, PhysicalRun, Submission
from training import streams
from training.models import scaled_speeds, top_speed


def event_group(event_id: int) -> str:
    return f"event_{event_id}"


def announce_leaderboard(event: Event, **details) -> None:
    """The event's rankings changed: after the change is committed, every page that shows them
    hears it."""
    message = {"type": "leaderboard", "event": event.pk, **details}
    transaction.on_commit(lambda: streams.send(event_group(event.pk), _update(message)))


def announce_submission(submission: Submission, *, ranked: bool = False) -> None:
    """A submission's status or score, for its event's pages; ``ranked`` when it changed the
    leaderboard."""
    message = {
        "type": "submission",
        "event": submission.event_id,
        "submission": submission.pk,
        "status": submission.status,
        "status_display": submission.get_status_display(),
        "score_ms": submission.score_ms,
        "qualified": submission.qualified,
        "ranked": ranked,
    }
    transaction.on_commit(lambda: streams.send(event_group(submission.event_id), _update(message)))


def timing_state(run: PhysicalRun | None) -> dict:
    """The car on the track as the timing pages show it (None: nobody is on the track)."""
    if run is None:
        return {"type": "timing", "on_track": False, "server_ms": _now_ms()}
    submission = run.submission
    rows = list(submission.laps.order_by("number"))
    short = scoring.far_below([lap.scoring_lap() for lap in rows])
    laps = [
        {
            "number": lap.number,
            "time_ms": lap.time_ms,
            "penalty_ms": lap.penalty_ms,
            "off_tracks": lap.off_tracks,
            "resets": lap.resets,
            "counted": lap.counted,
            "struck": lap.struck_at is not None,
            "far_below": far_below and lap.struck_at is None,
        }
        for lap, far_below in zip(rows, short, strict=True)
    ]
    started, ends = run.line_crossed_at, run.race_ends_at
    return {
        "type": "timing",
        "event": submission.event_id,
        "on_track": submission.status == Submission.Status.IN_PROGRESS,
        "submission": submission.pk,
        "racer": racer_name(racer=submission.racer),
        "model_name": submission.model_name,
        "car": run.car,
        "laps": laps,
        "off_tracks": run.off_tracks,
        "resets": run.resets,
        # the lap on track started then, in the server's epoch milliseconds; with server_ms a page
        # sets its timer against its own clock, whatever that clock says
        "lap_started_ms": None if started is None else round(started.timestamp() * 1000),
        # the racer's race time runs out then (None: no race time, or not started)
        "race_ends_ms": None if ends is None else round(ends.timestamp() * 1000),
        "race_time_min": submission.event.race_time_min,
        "server_ms": _now_ms(),
        "score_ms": submission.score_ms,
        "qualified": submission.qualified,
        "verdict": _verdict(submission, rows),
    }


def _verdict(submission: Submission, laps: list) -> str:
    """A finished run's result in the timekeeper's words: its score, or why it did not qualify
    ("did not qualify: 2 of the 3 counted laps in a row the event needs")."""
    if submission.status != Submission.Status.COMPLETED:
        return ""
    name = racer_name(racer=submission.racer)
    if submission.qualified and submission.score_ms is not None:
        return f"{name}'s run scored {laptime(submission.score_ms)}."
    needed = submission.event.laps_to_qualify
    if needed == 1:
        return f"{name}'s run did not qualify: it has no counted lap."
    done = scoring.counted_in_a_row([lap.scoring_lap() for lap in laps])
    return (
        f"{name}'s run did not qualify: {done} of the {needed} counted laps in a row the "
        "event needs."
    )


def announce_timing(run: PhysicalRun) -> None:
    """The car on the track changed (a crossing, an off-track, an undo, the finish)."""
    event_id = run.submission.event_id

    def send() -> None:
        run.refresh_from_db()
        run.submission.refresh_from_db()
        streams.send(event_group(event_id), _update(timing_state(run)))

    transaction.on_commit(send)


def queue_state(session: LiveSession | None) -> dict:
    """A live session's queue as the race and broadcast pages show it: the turn driving (its
    first car, with its evaluation, whose frames the pages watch, and every car of it in grid
    order), then the racers waiting, in order."""
    if session is None:
        return {"type": "queue", "open": False, "entries": [], "driving": None, "cars": []}
    entries = session.entries.select_related("racer__profile", "submission__evaluation", "model")
    entries = entries.order_by("position", "pk")
    shown, cars = [], []
    for entry in entries:
        row = {
            "id": entry.pk,
            "racer": racer_name(racer=entry.racer),
            "model_name": entry.model_name,
            "speed": entry.speed,
            **_speeds(entry),
            "status": entry.status,
            "submission": entry.submission_id,
            "evaluation": entry.submission.evaluation_id if entry.submission else None,
            "score_ms": entry.submission.score_ms if entry.submission else None,
        }
        if entry.status == entry.Status.DRIVING:
            evaluation = entry.submission.evaluation if entry.submission else None
            cars.append((evaluation.grid_position if evaluation else 0, row))
        elif entry.status != entry.Status.REMOVED:
            shown.append(row)
    cars = [row for _, row in sorted(cars, key=lambda car: car[0])]
    waiting = [row for row in shown if row["status"] == LiveEntry.Status.WAITING]
    for place, row in enumerate(waiting, start=1):  # the facilitator moves only what can move
        row.update(place=place, first_waiting=place == 1, last_waiting=place == len(waiting))
    return {
        "type": "queue",
        "open": True,
        "event": session.event_id,
        "autolaunch": session.autolaunch,
        "min_speed": session.min_speed,
        "max_speed": session.max_speed,
        "entries": shown,
        "driving": cars[0] if cars else None,
        "cars": cars,
    }


def _speeds(entry: LiveEntry) -> dict:
    """What the speed multiplier makes of the model's speeds: its fastest action's speed as
    driven [m/s], and whether the car's limit (4 m/s) cut it, so a racer sees what 1.2x does."""
    if entry.model is None:
        return {"top_speed": None, "capped": False}
    fastest = top_speed(entry.model.action_space)
    driven = top_speed(scaled_speeds(entry.model.action_space, entry.speed))
    return {"top_speed": driven, "capped": driven < fastest * entry.speed - 1e-9}


def announce_queue(session: LiveSession) -> None:
    """A live session's queue or turn changed."""
    event_id = session.event_id

    def send() -> None:
        current = LiveSession.objects.filter(pk=session.pk).first()
        streams.send(event_group(event_id), _update(queue_state(current)))

    transaction.on_commit(send)


def announce_winner(event: Event, ranking: dict | None) -> None:
    """The organiser shows the winner on the broadcast: ``ranking`` is the leader (None: none)."""
    message = {"type": "winner", "event": event.pk, "winner": ranking}
    transaction.on_commit(lambda: streams.send(event_group(event.pk), _update(message)))


def _now_ms() -> int:
    return round(time.time() * 1000)


def _update(message: dict) -> dict:
    return {"type": "event.update", "message": message}
