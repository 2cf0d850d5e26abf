from django.http import HttpRequest, HttpResponse
from django.shortcuts import get_object_or_404, render

from racing import selectors
from racing.models import Event


def race_list(request: HttpRequest) -> HttpResponse:
    return render(request, "racing/race_list.html", {"seasons": selectors.seasons_with_events()})


def leaderboard_list(request: HttpRequest) -> HttpResponse:
    return render(
        request, "racing/leaderboard_list.html", {"events": selectors.events_with_leaders()}
    )


def leaderboard(request: HttpRequest, slug: str) -> HttpResponse:
    event = get_object_or_404(Event.objects.select_related("season", "track"), slug=slug)
    return render(
        request,
        "racing/leaderboard.html",
        {"event": event, "rankings": selectors.leaderboard_for_event(event=event)},
    )
