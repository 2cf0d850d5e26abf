"""Pages and endpoints of physical events (``racing.timing``): the timekeeper's page, the
broadcast page for a projector or a stream, and the endpoint a timing device posts to.

The device endpoint, ``POST /api/timing/<event slug>/``, takes JSON ``{"signal": "crossing",
"at_ms": 123456}`` (the device's own clock, in whole milliseconds: only differences of its
readings matter) or ``{"signal": "off_track" | "reset" | "undo" | "finish"}``, with the header
``Authorization: Bearer <token>``, the event's device token (made on its timekeeper page, shown
once). It answers 200 with the timing state, 400 for a signal it cannot read, 401 for a missing
or wrong token, 404 for an event that is not raced by real cars, 409 when no car is on the
track or the signal does not fit the run (a second crossing within a second, say), each with
``{"error": "..."}``.
"""

from __future__ import annotations

import json

from django.conf import settings
from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.http import Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import redirect, render
from django.views.decorators.csrf import csrf_exempt
from django.views.decorators.http import require_POST

from racing import live, live_races, selectors, services, timing
from racing.forms import TimedRunForm
from racing.models import Event, LiveSession
from racing.views import _get_event_for_user, _get_event_run_by

TOP = 10  # the broadcast's leaderboard


def _event_to_time(request: HttpRequest, slug: str) -> Event:
    return _get_event_run_by(request, slug, timing.may_keep_time)


@login_required
def timekeeper(request: HttpRequest, slug: str) -> HttpResponse:
    event = _event_to_time(request, slug)
    form = TimedRunForm(request.POST or None)
    if request.method == "POST" and form.is_valid():
        data = form.cleaned_data
        try:
            timing.physical_run_start(
                event=event,
                racer=data["racer"],
                model_name=data["model_name"],
                car=data["car"],
                timekeeper=request.user,
            )
        except timing.TimingRefused as refused:
            form.add_error(None, str(refused))
        else:
            return redirect("racing:timekeeper", slug=event.slug)
    state = live.timing_state(timing.running_run(event=event))
    return render(
        request,
        "racing/timekeeper.html",
        {"event": event, "form": form, "state": state, "token": request.session.pop("token", "")},
    )


@login_required
@require_POST
def timekeeper_signal(request: HttpRequest, slug: str) -> JsonResponse:
    """The timekeeper page's keys, as the device endpoint's signals."""
    event = _event_to_time(request, slug)
    return _signal(event, request.body)


@login_required
@require_POST
def timekeeper_token(request: HttpRequest, slug: str) -> HttpResponse:
    event = _event_to_time(request, slug)
    request.session["token"] = timing.timing_token_renew(event=event)
    messages.success(request, "A new device token: the old one no longer works.")
    return redirect("racing:timekeeper", slug=event.slug)


@login_required
@require_POST
def winner(request: HttpRequest, slug: str) -> HttpResponse:
    """The broadcast's winner overlay, shown by the timekeeper or the live race's facilitator."""
    event = _get_event_for_user(request, slug)
    user = request.user
    if event.physical and timing.may_keep_time(event=event, user=user):
        back = "racing:timekeeper"
    elif live_races.may_facilitate(event=event, user=user):
        back = "racing:live-race"
    else:
        raise Http404("No such event to run.")
    shown = request.POST.get("show", "1") != "0"
    winner = services.event_winner_show(event=event, shown=shown)
    if not shown:
        messages.success(request, "The broadcast no longer shows the winner.")
    elif winner is None:
        messages.warning(
            request, "Nobody is ranked yet: the broadcast will show the winner once someone is."
        )
    else:
        messages.success(request, f"The broadcast shows the winner: {winner['racer']}.")
    return redirect(back, slug=event.slug)


def broadcast(request: HttpRequest, slug: str) -> HttpResponse:
    event = _get_event_for_user(request, slug)
    speedup = settings.PITLANE_WATCHED_SPEEDUP
    return render(request, "racing/broadcast.html", {"event": event, "speedup": speedup})


def broadcast_state(request: HttpRequest, slug: str) -> JsonResponse:
    """What the broadcast shows: the car on the track (a physical event's run, or a live race's
    turn) and the top ten."""
    event = _get_event_for_user(request, slug)
    run = timing.running_run(event=event) if event.physical else None
    session = None if event.physical else LiveSession.objects.filter(event=event).first()
    return JsonResponse(
        {
            "timing": live.timing_state(run),
            "queue": live.queue_state(session),
            "top": selectors.top_entries(event=event, count=TOP),
            "winner": selectors.winner_shown(event=event),
        }
    )


@csrf_exempt
@require_POST
def device(request: HttpRequest, slug: str) -> JsonResponse:
    """A timing device's signal (the module's docstring gives the protocol)."""
    event = Event.objects.filter(slug=slug, physical=True).first()
    if event is None:
        return JsonResponse({"error": "No event of that name is raced by real cars."}, status=404)
    scheme, _, token = request.headers.get("Authorization", "").partition(" ")
    if scheme.lower() != "bearer" or not timing.timing_token_matches(event=event, token=token):
        return JsonResponse({"error": "A wrong or missing device token."}, status=401)
    return _signal(event, request.body)


def _signal(event: Event, body: bytes) -> JsonResponse:
    try:
        data = json.loads(body or b"{}")
        kind, at_ms = data["signal"], data.get("at_ms")
        if not isinstance(kind, str) or not (at_ms is None or type(at_ms) is int):
            raise TypeError
    except (ValueError, KeyError, TypeError, AttributeError):
        return JsonResponse(
            {
                "error": 'Send JSON: {"signal": "crossing", "at_ms": <whole milliseconds>}, or a '
                "signal of off_track, reset, undo or finish."
            },
            status=400,
        )
    run = timing.running_run(event=event)
    if run is None:
        return JsonResponse({"error": "No car is on the track: start a run first."}, status=409)
    try:
        run = timing.run_signal(run=run, signal=timing.Signal(kind, at_ms))
    except timing.TimingRefused as refused:
        return JsonResponse({"error": str(refused)}, status=409)
    return JsonResponse(live.timing_state(run))
