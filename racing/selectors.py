"""Reads for the league."""

from __future__ import annotations

from django.db.models import Count, Min, QuerySet
from django.utils import timezone

from racing.models import Event, Ranking, Season


def seasons_with_events() -> QuerySet[Season]:
    return Season.objects.prefetch_related("events__track")


def events_with_leaders() -> QuerySet[Event]:
    return Event.objects.select_related("season", "track").annotate(
        entries=Count("rankings"), best_ms=Min("rankings__score_ms")
    )


def events_not_closed() -> QuerySet[Event]:
    """Open and upcoming events, soonest first."""
    return events_with_leaders().filter(closes_at__gt=timezone.now())


def leaderboard_for_event(*, event: Event) -> list[Ranking]:
    """The event's rankings in order, each with its ``position`` and ``gap_ms`` to first."""
    rankings = list(event.rankings.select_related("racer"))
    for position, ranking in enumerate(rankings, start=1):
        ranking.position = position
        ranking.gap_ms = ranking.score_ms - rankings[0].score_ms
    return rankings
