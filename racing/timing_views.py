"""Pages and endpoints of physical events (``racing.timing``): the timekeeper's page, the
broadcast page for a projector or a stream, and the endpoint a timing device posts to.

The device endpoint, ``POST /api/timing/<event slug>/``, takes JSON ``{"signal": "crossing",
"at_ms": 123456}`` (the device's own clock, in whole milliseconds: only differences of its
readings matter) or ``{"signal": "off_track" | "reset" | "undo" | "finish"}``, or DREM's lap
timer's events as it sends them (``timing_signals.DREM_EVENTS``), with the header
``Authorization: Bearer <token>``, the event's device token (made on its timekeeper page, shown
once). It answers 200 with the timing state; 400 for a body it cannot read (not JSON, an
unknown signal, a crossing without its whole-millisecond ``at_ms``); 401 for a missing or wrong
token; 404 for an event that is not raced by real cars; 409 when no car is on the track or the
signal does not fit the run (a crossing sooner than the event's shortest lap, say); each with
``{"error": "..."}``.

The timekeeper's page names racers by their racer name, searched as they type
(``timekeeper_racers``), and edits a run's laps during it and after it (``timed_run``,
``lap_edit``: ``racing.lap_edits``).
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

from racing import broadcasts, lap_edits, live_races, selectors, services, timing, timing_signals
from racing.forms import LapEditForm, TimedRunForm
from racing.models import Event, LiveSession, Submission
from racing.views import _get_event_for_user, _get_event_run_by

TOP = 10  # the broadcast's leaderboard


def _event_to_time(request: HttpRequest, slug: str) -> Event:
    return _get_event_run_by(request, slug, timing.may_keep_time)


@login_required
def timekeeper(request: HttpRequest, slug: str) -> HttpResponse:
    event = _event_to_time(request, slug)
    racers = timing.racers_timed_by(event=event, timekeeper=request.user)
    form = TimedRunForm(request.POST or None, racers=racers)
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
    state = broadcasts.timing_state(timing.running_run(event=event))
    context = {
        "event": event,
        "form": form,
        "state": state,
        "token": request.session.pop("token", ""),
        "runs": timing.timed_runs(event=event),
    }
    return render(request, "racing/timekeeper.html", context)


@login_required
def timekeeper_racers(request: HttpRequest, slug: str) -> JsonResponse:
    """The racer names that match what the timekeeper typed (``?q=``), at most ten."""
    event = _event_to_time(request, slug)
    text = request.GET.get("q", "")[:64]
    racers = timing.racers_timed_by(event=event, timekeeper=request.user)
    return JsonResponse({"racers": timing.racers_named_like(text=text, among=racers)})


def _run_to_edit(request: HttpRequest, slug: str, pk: int) -> tuple[Event, Submission]:
    """A run by a real car in an event this user times; 404 otherwise."""
    event = _event_to_time(request, slug)
    submission = Submission.objects.filter(pk=pk, event=event, physical=True).first()
    if submission is None:
        raise Http404("No such run in this event.")
    return event, submission


@login_required
def timed_run(request: HttpRequest, slug: str, pk: int) -> HttpResponse:
    """A run's laps, with what the timekeeper may change in them and who changed what."""
    event, submission = _run_to_edit(request, slug, pk)
    laps = list(submission.laps.select_related("struck_by__profile").order_by("number"))
    state = broadcasts.timing_state(getattr(submission, "physical_run", None))
    for lap, shown in zip(laps, state.get("laps", []), strict=False):
        lap.far_below = shown["far_below"]
    context = {
        "event": event,
        "submission": submission,
        "laps": laps,
        "state": state,
        "edits": submission.lap_edits.select_related("by__profile"),
        "split_form": LapEditForm(initial={"action": "split"}, submission=submission),
        "add_form": LapEditForm(initial={"action": "add"}, submission=submission),
    }
    return render(request, "racing/timed_run.html", context)


@login_required
@require_POST
def lap_edit(request: HttpRequest, slug: str, pk: int) -> HttpResponse:
    """One edit of a run's laps; JSON (the run's new state, or the error) for the page's
    scripts, a message and the run's page otherwise."""
    event, submission = _run_to_edit(request, slug, pk)
    form = LapEditForm(request.POST, submission=submission)
    error = ""
    if form.is_valid():
        try:
            done = _lap_edit_apply(form.cleaned_data, submission, request.user)
        except timing.TimingRefused as refused:
            error = str(refused)
    else:
        error = " ".join(message for errors in form.errors.values() for message in errors)
    if "application/json" in request.headers.get("Accept", ""):
        if error:  # a form it cannot read is the request's fault; a refused edit, the run's state
            return JsonResponse({"error": error}, status=409 if form.is_valid() else 400)
        submission.refresh_from_db()
        return JsonResponse(broadcasts.timing_state(getattr(submission, "physical_run", None)))
    if error:
        messages.error(request, error)
    else:
        messages.success(request, done)
    return redirect("racing:timed-run", slug=event.slug, pk=submission.pk)


def _lap_edit_apply(data: dict, submission: Submission, user) -> str:
    """Call the edit's service; what was done, in words."""
    action = data["action"]
    if action == "add":
        lap = lap_edits.lap_add(
            submission=submission,
            time_ms=data["time_ms"],
            off_tracks=data.get("off_tracks") or 0,
            by=user,
        )
        return f"Lap {lap.number} added."
    lap = data["lap_row"]
    if action == "strike":
        lap_edits.lap_strike(lap=lap, by=user)
        return f"Lap {lap.number} is struck out: it no longer counts."
    if action == "restore":
        lap_edits.lap_restore(lap=lap, by=user)
        return f"Lap {lap.number} is restored."
    second = lap_edits.lap_split(lap=lap, first_ms=data["first_ms"], by=user)
    return f"Lap {lap.number} is split: lap {second.number} is the rest of it."


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
            request, "Nobody is ranked yet: there is no winner to show. Show it once someone is."
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
    run = timing.shown_run(event=event) if event.physical else None
    session = None if event.physical else LiveSession.objects.filter(event=event).first()
    return JsonResponse(
        {
            "timing": broadcasts.timing_state(run),
            "queue": broadcasts.queue_state(session),
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
        signal = timing_signals.signal_read(json.loads(body or b"{}"))
    except (ValueError, RecursionError) as unreadable:  # not JSON, not a signal, too deep
        readable = isinstance(unreadable, timing_signals.SignalUnreadable)
        return JsonResponse(
            {"error": str(unreadable) if readable else timing_signals.SIGNAL_FORMAT}, status=400
        )
    run = timing.running_run(event=event)
    if signal.kind == timing_signals.HELLO:  # a lap timer that connected: nothing to do yet
        return JsonResponse(broadcasts.timing_state(run))
    if run is None:
        return JsonResponse({"error": "No car is on the track: start a run first."}, status=409)
    try:
        run = timing.run_signal(run=run, signal=signal)
    except timing.TimingRefused as refused:
        return JsonResponse({"error": str(refused)}, status=409)
    return JsonResponse(broadcasts.timing_state(run))
