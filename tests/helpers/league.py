"""Events, submissions and laps in the states the league tests need."""

from __future__ import annotations

import importlib
import itertools
from datetime import timedelta

from django.contrib.auth.models import Group, Permission
from django.utils import timezone

from racing import services
from racing.models import Division, Event, Season, Submission
from training.models import EvaluationJob, EvaluationTrial, RaceType, Track

DAY = timedelta(days=1)


def season() -> Season:
    today = timezone.localdate()
    return Season.objects.get_or_create(
        name="Test season",
        defaults={"year": today.year, "starts_on": today - 400 * DAY, "ends_on": today + 400 * DAY},
    )[0]


def event(name: str = "Time trial", *, opens=-DAY, closes=DAY, **fields) -> Event:
    """A public event (open now, by default) of the test season; ``opens``/``closes`` are
    offsets from now."""
    now = timezone.now()
    fields = {
        "season": season(),
        "name": name,
        "slug": name.lower().replace(" ", "-"),
        "track": Track.objects.get(name="pitlane-oval"),
        "race_type": RaceType.TIME_TRIAL,
        "division": Division.OPEN,
        "opens_at": now + opens,
        "closes_at": now + closes,
        **fields,
    }
    event = Event(**fields)
    event.full_clean()
    event.save()
    return event


def scored(
    event: Event, racer, *times: int | None, model_name: str = "m", at=None, off_tracks=()
) -> Submission:
    """A submission scored from lap times in ms (None: a lap cut short by time), with each lap's
    ``off_tracks`` when given."""
    submission = Submission.objects.create(event=event, racer=racer, model_name=model_name)
    services.SUBMISSION.move(submission, Submission.Status.IN_PROGRESS)  # as its race task does
    if at is not None:
        Submission.objects.filter(pk=submission.pk).update(created_at=at)
        submission.refresh_from_db()
    trials = [
        EvaluationTrial(
            number=number,
            time_ms=time or 5_000,
            progress=100 if time else 40,
            status="lap_complete" if time else "time_up",
            off_tracks=off,
        )
        for number, (time, off) in enumerate(
            itertools.zip_longest(times, off_tracks[: len(times)], fillvalue=0), start=1
        )
    ]
    return services.submission_score(submission=submission, trials=trials)


def race_evaluation(model, event: Event, *, checkpoint: str = "best", **fields) -> EvaluationJob:
    return EvaluationJob.objects.create(
        model=model, **services.race_rules(event, checkpoint=checkpoint), **fields
    )


def race_staff_group() -> Group:
    """The "Race staff" group with the rights its migrations give it (racing's 0003 and 0009):
    a transactional test's flush removes what migrations wrote, and the suite's processes run
    tests in no fixed order, so a test that needs the group cannot count on it being there."""
    rights = [
        *importlib.import_module("racing.migrations.0003_race_staff").MODELS,
        *importlib.import_module("racing.migrations.0009_race_staff_live_and_physical").MODELS,
    ]
    group, _ = Group.objects.get_or_create(name="Race staff")
    group.permissions.add(
        *Permission.objects.filter(content_type__app_label="racing", content_type__model__in=rights)
    )
    return group
