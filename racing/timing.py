"""Physical events: real cars timed at the track, scored into the same leaderboards.

A timekeeper (staff, or a community race's organiser) starts a run for a racer's car; each time the
car crosses the line the timekeeper presses a key on the event's timekeeper page, or a timing device
posts a crossing (``racing.timing_views.device``, read by ``racing.timing_signals``). The first
crossing starts the clock, each later one ends a lap: its time is the difference of two readings of
the same clock (the page's or the device's), plus the event's off-track penalty for each off-track
marked during it. A lap counts when it has no more off-tracks than the event allows. Finishing the
run scores its laps by the event's ranking method (best lap, first N consecutive, best average of N,
total time: ``racing.scoring``) and offers the score to the racer's ranking, as a simulated race's
is.

Signals, from the page's keys or the device's ``signal``:

- ``crossing`` (the space bar): the car crossed the line, at the clock's ``at_ms``;
- ``off_track`` (O): the car left the track and drove back on;
- ``reset`` (R): the car left the track and was put back by hand (it counts as an off-track too,
  as a simulated car's reset follows its off-track);
- ``undo`` (U): the last crossing was a mistake: its lap goes, its off-tracks and resets return to
  the lap on track (the first crossing undone stops the clock);
- ``finish`` (F): the run is over: score it.

A crossing sooner than the event's shortest lap (``Event.min_lap_s``) after the last one is
refused in words (a double press, a gate's bounce); laps and clock readings are bounded by what a
race can take (``MAX_LAP_MS``, ``MAX_CLOCK_MS``), so no reading can overflow a lap or an undo.
After a crossing, or after the finish, the timekeeper may strike a lap out, restore it, or add a
crossing they missed (``racing.lap_edits``); a finished run is then scored again.

The DeepRacer Event Manager times physical events the same way: a timekeeper records each lap and
its resets, and its leaderboards take the best lap or the best average of X laps.
"""

from __future__ import annotations

import hashlib
import hmac
import secrets
from datetime import datetime, timedelta

from django.contrib.auth import get_user_model
from django.contrib.auth.models import AbstractBaseUser
from django.db import transaction
from django.db.models import Q, QuerySet
from django.utils import timezone

from accounts.selectors import racer_name
from common.formatting import laptime
from common.refusals import Refused
from notifications import services as notifications
from racing import broadcasts, scoring, selectors
from racing.models import Event, Lap, PhysicalRun, Submission
from racing.services import SUBMISSION, ranking_offer, ranking_recompute
from racing.timing_signals import MAX_CLOCK_MS, SIGNALS, Signal

MAX_LAP_MS = 3 * 3600 * 1000  # no lap of a race night takes longer: a longer one is a clock's slip
MAX_OFF_TRACKS = 999  # off-tracks in one lap
RACERS_SHOWN = 10  # the racer search's answers, at most


class TimingRefused(Refused):
    """The signal cannot be taken; the message says why, in the timekeeper's words."""


def timing_token_renew(*, event: Event) -> str:
    """A new token for the event's timing device (the old one stops working): shown once, kept
    only as its hash."""
    token = secrets.token_urlsafe(32)
    Event.objects.filter(pk=event.pk).update(timing_token_hash=_digest(token))
    event.timing_token_hash = _digest(token)
    return token


def timing_token_matches(*, event: Event, token: str) -> bool:
    """Whether ``token`` is the event's device token (compared in constant time)."""
    if not event.timing_token_hash or not token:
        return False
    return hmac.compare_digest(event.timing_token_hash, _digest(token))


def _digest(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def racers_timed_by(*, event: Event, timekeeper: AbstractBaseUser) -> QuerySet:
    """The racers ``timekeeper`` may put on the track in ``event``: any active racer for league
    staff; for a community race's organiser, only its participants and themselves, so that an
    organiser can neither time, notify nor look up anyone else on the console."""
    racers = get_user_model().objects.filter(is_active=True, profile__isnull=False)
    if timekeeper.is_staff:
        return racers
    joined = Q(joined_events=event) & ~Q(removed_from_events=event)
    return racers.filter(joined | Q(pk=event.organiser_id)).distinct()


def racers_named_like(*, text: str, among: QuerySet, limit: int = RACERS_SHOWN) -> list[str]:
    """The racer names ``among`` those racers that start with ``text`` (then those that hold
    it), any case, at most ``limit``: the timekeeper's search as they type. Never a login
    name."""
    text = text.strip()
    if not text:
        return []
    names = (
        among.filter(profile__racer_name__icontains=text)
        .annotate(starts=Q(profile__racer_name__istartswith=text))
        .order_by("-starts", "profile__racer_name")
        .values_list("profile__racer_name", flat=True)
    )
    return list(names[:limit])  # ordered and cut in the database: "a" reads ten rows, not all


def racer_named(*, name: str, among: QuerySet) -> AbstractBaseUser:
    """The racer ``among`` those called ``name`` (any case); ``TimingRefused`` says, in words,
    when nobody is, naming the racers it may have meant (the same words for a racer who is not
    among them as for one who does not exist)."""
    name = name.strip()
    racer = among.filter(profile__racer_name__iexact=name).first()
    if racer is not None:
        return racer
    alike = racers_named_like(text=name, among=among, limit=4)
    if not alike:
        raise TimingRefused(f"No racer is called {name}: check the spelling of their racer name.")
    if len(alike) == 1:
        raise TimingRefused(f"No racer is called {name}: did you mean {alike[0]}?")
    raise TimingRefused(
        f"No racer is called {name}, and {len(alike)} names hold it ({', '.join(alike)}): "
        "type the whole racer name."
    )


def physical_run_start(
    *, event: Event, racer: AbstractBaseUser, model_name: str, car: str, timekeeper
) -> PhysicalRun:
    """A racer's car on the track: a physical submission, its clock not yet started. One car is
    timed at a time in an event."""
    if not event.physical:
        raise TimingRefused(f"{event.name} is not raced by real cars: its laps are simulated.")
    if event.state == Event.State.CLOSED:
        raise TimingRefused(f"{event.name} has closed: no more runs are timed.")
    if not racers_timed_by(event=event, timekeeper=timekeeper).filter(pk=racer.pk).exists():
        raise TimingRefused(f"No racer is called {racer_name(racer=racer)} in {event.name}.")
    with transaction.atomic():
        Event.objects.select_for_update().filter(pk=event.pk).first()  # one start at a time
        if (running := running_run(event=event)) is not None:
            raise TimingRefused(
                f"{running.car} ({racer_name(racer=running.submission.racer)}) is still on the "
                "track: finish that run first."
            )
        submission = Submission.objects.create(
            event=event, racer=racer, model_name=model_name, physical=True
        )
        SUBMISSION.move(submission, Submission.Status.IN_PROGRESS)
        run = PhysicalRun.objects.create(submission=submission, car=car, timekeeper=timekeeper)
    broadcasts.announce_timing(run)
    return run


def running_run(*, event: Event) -> PhysicalRun | None:
    """The run on the track in ``event``, if any."""
    return (
        PhysicalRun.objects.select_related("submission__racer", "submission__event")
        .filter(submission__event=event, submission__status=Submission.Status.IN_PROGRESS)
        .first()
    )


def shown_run(*, event: Event) -> PhysicalRun | None:
    """The run the broadcast shows: the one on the track, else the last one timed, with its laps
    and result, until the next car starts (as a live race's last turn stays shown)."""
    found = running_run(event=event)
    if found is not None:
        return found
    runs = PhysicalRun.objects.select_related("submission__racer", "submission__event")
    return runs.filter(submission__event=event).order_by("-submission__created_at", "-pk").first()


def run_signal(*, run: PhysicalRun, signal: Signal) -> PhysicalRun:
    """Apply one signal to the run on the track; its pages hear the new state."""
    if signal.kind not in SIGNALS:
        raise TimingRefused(f"Unknown signal {signal.kind!r}: send one of {', '.join(SIGNALS)}.")
    if signal.kind == "finish":
        return physical_run_finish(run=run)
    with transaction.atomic():
        run = _locked(run)
        if signal.kind == "crossing":
            _crossing(run, signal.at_ms)
        elif signal.kind == "undo":
            _undo(run)
        else:
            if run.off_tracks >= MAX_OFF_TRACKS:
                raise TimingRefused(f"{MAX_OFF_TRACKS} off-tracks on one lap is all a lap holds.")
            run.off_tracks += 1
            run.resets += signal.kind == "reset"
            run.save(update_fields=["off_tracks", "resets"])
    broadcasts.announce_timing(run)
    return run


def _locked(run: PhysicalRun) -> PhysicalRun:
    """``run``, freshly read under its submission's lock: the lock the timekeeper's lap edits
    take too (``lap_edits``), so a signal and an edit of one run never interleave."""
    Submission.objects.select_for_update().filter(pk=run.submission_id).first()
    locked = (
        PhysicalRun.objects.select_for_update()
        .select_related("submission__event", "submission__racer")
        .filter(pk=run.pk)
        .first()
    )
    if locked is None or locked.submission.status != Submission.Status.IN_PROGRESS:
        raise TimingRefused("That run is over: start the next one.")
    return locked


def _crossing(run: PhysicalRun, at_ms: int | None) -> None:
    if at_ms is None or not 0 <= at_ms < MAX_CLOCK_MS:
        raise TimingRefused("A crossing needs the clock's reading, at_ms: whole milliseconds.")
    now = timezone.now()
    if run.line_crossed_ms is None:
        run.started_at = now  # the racer's race time runs from the first crossing
    else:
        event = run.submission.event
        _race_time_refusal(run, now)
        lap_refusal(event=event, lap_ms=at_ms - run.line_crossed_ms)
        penalty_ms = penalty_for(event=event, off_tracks=run.off_tracks)
        Lap.objects.create(
            submission=run.submission,
            number=run.submission.laps.count() + 1,
            time_ms=at_ms - run.line_crossed_ms + penalty_ms,
            penalty_ms=penalty_ms,
            status="lap_complete",
            off_tracks=run.off_tracks,
            resets=run.resets,
            counted=event.lap_counts(off_tracks=run.off_tracks),
        )
    run.line_crossed_ms, run.line_crossed_at = at_ms, now
    run.off_tracks = run.resets = 0
    run.save(
        update_fields=["started_at", "line_crossed_ms", "line_crossed_at", "off_tracks", "resets"]
    )


def _race_time_refusal(run: PhysicalRun, now: datetime) -> None:
    """``TimingRefused`` for a crossing after the racer's race time: as the DeepRacer Event
    Manager ends a race when its timer expires (website/src/pages/timekeeper/pages/
    racePage.tsx: RaceTimer's onExpire sends EXPIRE, whose endRace asks to end the race), the
    lap on track when time ran out is not counted."""
    ends = run.race_ends_at
    if ends is not None and now > ends:
        minutes = run.submission.event.race_time_min
        raise TimingRefused(
            f"The race time ({minutes} min from the first crossing) ran out "
            f"{laptime((now - ends).total_seconds() * 1000)} ago: this lap is not counted. "
            "Finish the run."
        )


def lap_refusal(*, event: Event, lap_ms: int, what: str = "A crossing") -> None:
    """``TimingRefused`` for a lap a real car cannot have driven: shorter than the event's
    shortest lap (the same crossing twice, or the clock went back), or longer than a race."""
    shortest = round(event.min_lap_s * 1000)
    if lap_ms < 0:
        raise TimingRefused(f"{what} before the last one: the clock went back. Not counted.")
    if lap_ms < shortest:
        raise TimingRefused(
            f"{what} {laptime(lap_ms)} after the last one: shorter than this event's shortest "
            f"lap ({event.min_lap_s:g} s), so the same crossing twice. Not counted."
        )
    if lap_ms > MAX_LAP_MS:
        raise TimingRefused(
            f"{what} {lap_ms // 60_000:,} minutes after the last one: longer than a race "
            f"({MAX_LAP_MS // 3_600_000} hours at most). Was the clock reset? Not counted."
        )


def penalty_for(*, event: Event, off_tracks: int) -> int:
    """The event's off-track penalty for ``off_tracks`` [ms]."""
    return round(off_tracks * event.off_track_penalty_s * 1000)


def _undo(run: PhysicalRun) -> None:
    last = run.submission.laps.order_by("-number").first()
    if last is None:
        if run.line_crossed_ms is None:
            raise TimingRefused("Nothing to undo: the car has not crossed the line yet.")
        run.line_crossed_ms = run.line_crossed_at = run.started_at = None  # the clocks stop
    else:
        run.line_crossed_ms -= last.time_ms - last.penalty_ms
        run.line_crossed_at = (run.line_crossed_at or timezone.now()) - timedelta(
            milliseconds=last.time_ms - last.penalty_ms
        )
        run.off_tracks += last.off_tracks
        run.resets += last.resets
        last.delete()
    run.save(
        update_fields=["started_at", "line_crossed_ms", "line_crossed_at", "off_tracks", "resets"]
    )


def physical_run_finish(*, run: PhysicalRun) -> PhysicalRun:
    """The run is over: score its laps by the event's rules, offer the score to the racer's
    ranking, and tell the racer."""
    with transaction.atomic():
        run = _locked(run)
        submission = run.submission
        SUBMISSION.move(
            submission,
            Submission.Status.COMPLETED,
            finished_at=timezone.now(),
            **_scored(submission),
        )
        ranked = ranking_offer(submission=submission)
    broadcasts.announce_submission(submission, ranked=ranked)
    broadcasts.announce_timing(run)
    notifications.submission_scored(submission=submission)
    return run


def physical_run_rescore(*, submission: Submission) -> Submission:
    """A finished run's laps were edited: score them again by the event's rules. The racer's
    ranking is made again from all their runs (``ranking_recompute``), so a score that got worse
    gives way to their next best, or leaves the leaderboard; its pages hear the change."""
    with transaction.atomic():
        locked = Submission.objects.select_for_update().filter(pk=submission.pk).first()
        before = (locked.score_ms, locked.qualified)
        fields = _scored(submission)
        Submission.objects.filter(pk=submission.pk).update(**fields)
        for name, value in fields.items():
            setattr(submission, name, value)
        ranking_recompute(event=submission.event, racer=submission.racer)
    broadcasts.announce_submission(submission, ranked=True)
    broadcasts.announce_leaderboard(submission.event, submission=submission.pk)
    if (submission.score_ms, submission.qualified) != before:  # the racer hears the new score
        notifications.submission_scored(submission=submission)
    return submission


def _scored(submission: Submission) -> dict:
    """The submission's score fields from its laps, by the event's method; a best-lap event
    raced by real cars ranks any counted lap (``Event.laps_to_qualify``)."""
    event = submission.event
    laps = list(submission.laps.order_by("number"))
    score = scoring.score(
        [lap.scoring_lap() for lap in laps],
        method=event.ranking_method,
        size=event.laps_to_qualify,
    )
    return {
        "score_ms": score,
        "qualified": score is not None,
        "laps_completed": len(laps),
        "off_tracks": sum(lap.off_tracks for lap in laps),
    }


def timed_runs(*, event: Event, count: int = 10) -> QuerySet:
    """The event's last ``count`` runs by real cars, newest first (the timekeeper's list)."""
    runs = Submission.objects.filter(event=event, physical=True).select_related(
        "racer__profile", "physical_run"
    )
    return runs.order_by("-created_at", "-pk")[:count]


def may_keep_time(*, event: Event, user: AbstractBaseUser) -> bool:
    """Staff time any physical event; a community race's organiser times their own."""
    if not user.is_authenticated or not event.physical:
        return False
    if user.is_staff:
        return selectors.event_visible_to(event=event, user=user)
    return event.organiser_id == user.pk
