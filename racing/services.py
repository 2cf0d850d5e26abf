"""Writes for the league."""

from __future__ import annotations

import calendar
from datetime import date, datetime, time, timedelta

from django.db import transaction
from django.utils import timezone

from racing.models import Division, Event, RaceType, Season
from training.models import Track


@transaction.atomic
def demo_season_load(*, today: date | None = None) -> Season:
    """The demo season a fresh console starts with: one event open this month per division, and
    one that opens next month. Running it again changes nothing.
    """
    today = today or timezone.localdate()
    first = today.replace(day=1)
    last = today.replace(day=calendar.monthrange(today.year, today.month)[1])
    next_first = last + timedelta(days=1)
    next_last = next_first.replace(day=calendar.monthrange(next_first.year, next_first.month)[1])

    season, _ = Season.objects.get_or_create(
        name=f"Demo season {today.year}",
        defaults={
            "year": today.year,
            "starts_on": date(today.year, 1, 1),
            "ends_on": date(today.year, 12, 31),
        },
    )
    month = first.strftime("%B")
    next_month = next_first.strftime("%B")
    for slug, fields in {
        f"open-time-trial-{first:%Y-%m}": {
            "name": f"{month} Open time trial",
            "track": "pitlane-oval",
            "race_type": RaceType.TIME_TRIAL,
            "division": Division.OPEN,
            "window": (first, last),
        },
        f"pro-object-avoidance-{first:%Y-%m}": {
            "name": f"{month} Pro object avoidance",
            "track": "kidney-bean",
            "race_type": RaceType.OBJECT_AVOIDANCE,
            "division": Division.PRO,
            "window": (first, last),
        },
        f"open-time-trial-{next_first:%Y-%m}": {
            "name": f"{next_month} Open time trial",
            "track": "clover-loop",
            "race_type": RaceType.TIME_TRIAL,
            "division": Division.OPEN,
            "window": (next_first, next_last),
        },
    }.items():
        opens_on, closes_on = fields.pop("window")
        Event.objects.get_or_create(
            slug=slug,
            defaults={
                **fields,
                "season": season,
                "track": Track.objects.get(name=fields["track"]),
                "opens_at": _start_of(opens_on),
                "closes_at": _start_of(closes_on + timedelta(days=1)),
            },
        )
    return season


def _start_of(day: date) -> datetime:
    return timezone.make_aware(datetime.combine(day, time.min))
