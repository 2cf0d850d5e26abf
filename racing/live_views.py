"""The live race page (``racing.live_races``): the turn on the track, the queue, the leaderboard;
racers join the queue from it and the facilitator runs the session from it."""

from __future__ import annotations

from django.conf import settings
from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import Http404, HttpRequest, HttpResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.views.decorators.http import require_POST

from racing import broadcasts, live_races
from racing.forms import LiveJoinForm, LiveSessionForm
from racing.models import Event, LiveEntry, LiveSession
from racing.views import _get_event_for_user, _get_event_run_by

MOVES = {"up": -1, "down": 1}


def live_race(request: HttpRequest, slug: str) -> HttpResponse:
    event = _get_event_for_user(request, slug)
    if event.physical:
        return redirect("racing:broadcast", slug=event.slug)
    session = LiveSession.objects.filter(event=event).first()
    user = request.user
    facilitator = live_races.may_facilitate(event=event, user=user)
    join = None
    queued = session is not None and live_races.live_place_held(session=session, racer=user)
    if session is not None and user.is_authenticated and not queued:
        join = LiveJoinForm(request.POST or None, racer=user, session=session)
        if not join.fields["model"].queryset.exists():
            join = None  # nothing to race with: the page says how to get a model instead
        elif request.method == "POST" and join.is_valid():
            try:
                live_races.live_entry_join(
                    session=session,
                    racer=user,
                    model=join.cleaned_data["model"],
                    speed=join.cleaned_data["speed"],
                )
            except live_races.LiveRefused as refused:
                join.add_error(None, str(refused))
            else:
                messages.success(request, "You are in the queue: the page shows your turn.")
                return redirect("racing:live-race", slug=event.slug)
    mine = set()
    if session is not None and user.is_authenticated:
        waiting = session.entries.filter(racer=user, status=LiveEntry.Status.WAITING)
        mine = set(waiting.values_list("pk", flat=True))
    context = {
        "event": event,
        "session": session,
        "facilitator": facilitator,
        "join": join,
        "queued": queued,
        "mine": mine,
        "queue": broadcasts.queue_state(session),
        "speedup": settings.PITLANE_WATCHED_SPEEDUP,
        "settings_form": LiveSessionForm(initial=_settings(session)) if facilitator else None,
    }
    if request.GET.get("fragment") == "queue":
        return render(request, "racing/includes/live_queue.html", context)
    return render(request, "racing/live_race.html", context)


def _settings(session: LiveSession | None) -> dict:
    if session is None:
        return {}
    return {
        "min_speed": session.min_speed,
        "max_speed": session.max_speed,
        "autolaunch": session.autolaunch,
    }


def _facilitated(request: HttpRequest, slug: str) -> Event:
    return _get_event_run_by(request, slug, live_races.may_facilitate)


@login_required
@require_POST
def live_race_open(request: HttpRequest, slug: str) -> HttpResponse:
    event = _facilitated(request, slug)
    form = LiveSessionForm(request.POST)
    if not form.is_valid():
        for error in form.errors.values():
            messages.error(request, " ".join(error))
        return redirect("racing:live-race", slug=event.slug)
    try:
        live_races.live_session_open(event=event, facilitator=request.user, **form.cleaned_data)
    except live_races.LiveRefused as refused:
        messages.error(request, str(refused))
    return redirect("racing:live-race", slug=event.slug)


@login_required
@require_POST
def live_race_launch(request: HttpRequest, slug: str) -> HttpResponse:
    event = _facilitated(request, slug)
    session = get_object_or_404(LiveSession, event=event)
    try:
        entry = live_races.live_turn_launch(session=session)
    except live_races.LiveRefused as refused:
        messages.error(request, str(refused))
    else:
        messages.success(request, f"{entry.model_name} is on the track.")
    return redirect("racing:live-race", slug=event.slug)


@login_required
@require_POST
def live_entry_action(request: HttpRequest, slug: str, pk: int, action: str) -> HttpResponse:
    event = _facilitated(request, slug)
    entry = get_object_or_404(LiveEntry, pk=pk, session__event=event)
    try:
        if action in MOVES:
            live_races.live_entry_move(entry=entry, places=MOVES[action])
        elif action == "remove":
            live_races.live_entry_remove(entry=entry)
        elif action == "restart":
            live_races.live_entry_restart(entry=entry)
        else:
            raise Http404("No such action.")
    except live_races.LiveRefused as refused:
        messages.error(request, str(refused))
    return redirect("racing:live-race", slug=event.slug)


@login_required
@require_POST
def live_entry_leave(request: HttpRequest, slug: str, pk: int) -> HttpResponse:
    """A racer takes their own place out of the queue."""
    event = _get_event_for_user(request, slug)
    entry = get_object_or_404(LiveEntry, pk=pk, session__event=event, racer=request.user)
    try:
        live_races.live_entry_remove(entry=entry)
    except live_races.LiveRefused as refused:
        messages.error(request, str(refused))
    else:
        messages.success(request, "You left the queue.")
    return redirect("racing:live-race", slug=event.slug)
