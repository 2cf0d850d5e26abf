"""A real car's laps edited by its timekeeper, during the run or after it (``racing.timing``).

As DREM's race admin allows (guidance-for-aws-deepracer-event-management@18030a1: its timekeeper
marks a lap valid or not during the race, website/src/pages/timekeeper/pages/racePage.tsx:292-303;
its race admin deletes laps and edits a lap's time, resets and validity after it,
website/src/admin/race-admin/pages/editRace.tsx:82-124), the timekeeper may:

- strike a lap out: it stays in the run's table but no longer counts (a double press, a cut
  corner); restore it: it counts again where the event's rules say it does;
- split a lap in two at a crossing they missed: the lap's first part took ``first_ms`` and keeps
  its off-tracks, the rest is the next lap (each part at least the event's shortest lap);
- add a lap after the finish, at the end of the run: a crossing the timekeeper missed before
  they finished it, its time read off a stopwatch or a video.

Every edit keeps who made it and when (``LapEdit``; a struck lap also keeps ``struck_by`` and
``struck_at``). A finished run is scored again by the event's rules and the racer's ranking made
again from all their runs, better or worse (``timing.physical_run_rescore``); a run on the track
is shown anew on its pages.
"""

from __future__ import annotations

from django.contrib.auth.models import AbstractBaseUser
from django.db import transaction
from django.utils import timezone

from common.formatting import laptime
from racing import broadcasts
from racing.models import Lap, LapEdit, Submission
from racing.timing import (
    MAX_OFF_TRACKS,
    TimingRefused,
    lap_refusal,
    penalty_for,
    physical_run_rescore,
)


def lap_strike(*, lap: Lap, by: AbstractBaseUser) -> Lap:
    """Strike ``lap`` out: it no longer counts."""
    with transaction.atomic():
        lap = _locked(lap)
        if lap.struck_at is not None:
            raise TimingRefused(f"Lap {lap.number} is struck out already.")
        lap.counted, lap.struck_at, lap.struck_by = False, timezone.now(), by
        lap.save(update_fields=["counted", "struck_at", "struck_by"])
        _kept(lap.submission, lap.number, LapEdit.Action.STRIKE, laptime(lap.time_ms), by)
        _edited(lap.submission)
    return lap


def lap_restore(*, lap: Lap, by: AbstractBaseUser) -> Lap:
    """Count a struck lap again, where the event's rules count it."""
    with transaction.atomic():
        lap = _locked(lap)
        if lap.struck_at is None:
            raise TimingRefused(f"Lap {lap.number} is not struck out: nothing to restore.")
        lap.counted = lap.submission.event.lap_counts(off_tracks=lap.off_tracks)
        lap.struck_at = lap.struck_by = None
        lap.save(update_fields=["counted", "struck_at", "struck_by"])
        _kept(lap.submission, lap.number, LapEdit.Action.RESTORE, laptime(lap.time_ms), by)
        _edited(lap.submission)
    return lap


def lap_split(*, lap: Lap, first_ms: int, by: AbstractBaseUser) -> Lap:
    """A crossing was missed ``first_ms`` into ``lap``: the lap ends there (with its off-tracks)
    and the rest of it becomes the next lap; the laps after it move one number on. The new
    lap."""
    with transaction.atomic():
        lap = _locked(lap)
        submission, event = lap.submission, lap.submission.event
        if lap.struck_at is not None:
            raise TimingRefused(f"Lap {lap.number} is struck out: restore it before splitting it.")
        driven = lap.time_ms - lap.penalty_ms
        if first_ms >= driven:
            raise TimingRefused(
                f"Lap {lap.number} took {laptime(driven)} of driving: the missed crossing came "
                "before its end. Give a time within the lap."
            )
        lap_refusal(event=event, lap_ms=first_ms, what="The missed crossing came")
        lap_refusal(event=event, lap_ms=driven - first_ms, what="The next crossing came")
        for later in submission.laps.filter(number__gt=lap.number).order_by("-number"):
            later.number += 1
            later.save(update_fields=["number"])
        second = Lap.objects.create(
            submission=submission,
            number=lap.number + 1,
            time_ms=driven - first_ms,
            status="lap_complete",
            counted=event.lap_counts(off_tracks=0),
        )
        lap.time_ms = first_ms + lap.penalty_ms
        lap.save(update_fields=["time_ms"])
        detail = f"{laptime(driven)} into {laptime(first_ms)} and {laptime(second.time_ms)}"
        _kept(submission, lap.number, LapEdit.Action.SPLIT, detail, by)
        _edited(submission)
    return second


def lap_add(
    *, submission: Submission, time_ms: int, off_tracks: int = 0, by: AbstractBaseUser
) -> Lap:
    """A lap at the end of a finished run, ``time_ms`` of driving and ``off_tracks`` (the
    event's penalty added): a crossing missed before the finish. A run still on the track takes
    its crossings from the space bar or the device."""
    with transaction.atomic():
        submission = (
            Submission.objects.select_for_update().select_related("event").get(pk=submission.pk)
        )
        if submission.status != Submission.Status.COMPLETED:
            raise TimingRefused(
                "The car is still on the track: press the space bar as it crosses the line, "
                "or split a lap at a crossing you missed."
            )
        event = submission.event
        lap_refusal(event=event, lap_ms=time_ms, what="A lap of")
        if not 0 <= off_tracks <= MAX_OFF_TRACKS:
            raise TimingRefused(f"A lap has from 0 to {MAX_OFF_TRACKS} off-tracks.")
        penalty_ms = penalty_for(event=event, off_tracks=off_tracks)
        last = submission.laps.order_by("-number").first()
        lap = Lap.objects.create(
            submission=submission,
            number=(last.number if last else 0) + 1,
            time_ms=time_ms + penalty_ms,
            penalty_ms=penalty_ms,
            off_tracks=off_tracks,
            status="lap_complete",
            counted=event.lap_counts(off_tracks=off_tracks),
        )
        _kept(submission, lap.number, LapEdit.Action.ADD, laptime(lap.time_ms), by)
        _edited(submission)
    return lap


def _locked(lap: Lap) -> Lap:
    """``lap`` under a lock on its run (its laps change one edit at a time), freshly read;
    only a real car's laps are edited."""
    Submission.objects.select_for_update().filter(pk=lap.submission_id).first()
    fresh = Lap.objects.select_related("submission__event").filter(pk=lap.pk).first()
    if fresh is None or not fresh.submission.physical:
        raise TimingRefused("That lap is gone: the run was changed meanwhile. Reload the page.")
    return fresh


def _kept(
    submission: Submission, number: int, action: str, detail: str, by: AbstractBaseUser
) -> None:
    LapEdit.objects.create(
        submission=submission, lap_number=number, action=action, detail=detail[:200], by=by
    )


def _edited(submission: Submission) -> None:
    """A finished run is scored again; a run on the track is shown anew. Called under the run's
    lock (``_locked``), which the timekeeper's signals take too (``timing._locked``), so an edit,
    a crossing and a finish of one run happen one after the other."""
    submission.refresh_from_db()
    if submission.status == Submission.Status.COMPLETED:
        physical_run_rescore(submission=submission)
    elif (run := getattr(submission, "physical_run", None)) is not None:
        broadcasts.announce_timing(run)
