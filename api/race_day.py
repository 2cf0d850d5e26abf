"""Race day in the API: a live race's queue (racers join and leave it; its facilitator opens the
session, reorders the queue, takes racers out or puts them back, launches each turn) and the
broadcast's winner, with the live race page's rules (``racing.live_races``).

A racer's token needs the ``race`` scope. A facilitator is who the page lets facilitate: a
community race's organiser (with ``race``), or staff on any simulated event (with ``admin``,
as staff act through the API only with a staff token).
"""

from __future__ import annotations

from typing import Literal

from ninja import Router, Schema, Status

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError
from api.league import event_of
from api.owned import own_model
from api.schemas import REFUSED, named_choices
from racing import broadcasts, live_races, services, timing
from racing.models import Event, LiveEntry, LiveSession

router = Router()
QueueStatus = named_choices(LiveEntry.Status, "QueueStatus")
ACTIONS = {"up": -1, "down": 1}


class QueueEntry(Schema):
    id: int
    racer: str
    model_name: str
    speed: float
    status: QueueStatus
    place: int | None = None
    score_ms: int | None = None


class Queue(Schema):
    open: bool
    entries: list[QueueEntry]
    cars: list[QueueEntry]  # the turn driving now, in grid order


class SessionIn(Schema):
    min_speed: float = 0.5
    max_speed: float = 1.5
    autolaunch: bool = False


class JoinIn(Schema):
    model: int
    speed: float = 1.0


class WinnerIn(Schema):
    show: bool = True


class Winner(Schema):
    shown: bool
    winner: dict | None


@router.get("/{slug}/live", response={200: Queue, **REFUSED})
def live_queue(request, slug: str):
    """The event's live race: the turn on the track and the racers waiting, in order."""
    need(request, TokenScope.READ)
    return broadcasts.queue_state(_session(event_of(request, slug), opened=False))


@router.post("/{slug}/live", response={200: Queue, **REFUSED})
def live_open(request, slug: str, body: SessionIn):
    """Open the event's live session, or change its settings (facilitators)."""
    event = _facilitated(request, slug)
    try:
        session = live_races.live_session_open(event=event, facilitator=request.user, **body.dict())
    except live_races.LiveRefused as refused:
        raise ApiError(409, "refused", str(refused)) from None
    return broadcasts.queue_state(session)


@router.post("/{slug}/live/queue", response={201: QueueEntry, **REFUSED})
def live_join(request, slug: str, body: JoinIn):
    """Join the queue with one of your ready models at ``speed`` times its speeds."""
    need(request, TokenScope.RACE)
    session = _session(event_of(request, slug))
    model = own_model(request, body.model)
    try:
        entry = live_races.live_entry_join(
            session=session, racer=request.user, model=model, speed=body.speed
        )
    except live_races.LiveRefused as refused:
        raise ApiError(409, "refused", str(refused)) from None
    return Status(201, _entry_out(session, entry.pk))


@router.delete("/{slug}/live/queue/{entry_id}", response={200: Queue, **REFUSED})
def live_leave(request, slug: str, entry_id: int):
    """Take your own place out of the queue."""
    need(request, TokenScope.RACE)
    session = _session(event_of(request, slug))
    entry = session.entries.filter(pk=entry_id, racer=request.user).first()
    if entry is None:
        raise ApiError(404, "not_found", f"No place of yours in this queue has the id {entry_id}.")
    _refused_as_conflict(live_races.live_entry_remove, entry=entry)
    return broadcasts.queue_state(session)


@router.post("/{slug}/live/queue/{entry_id}/{action}", response={200: Queue, **REFUSED})
def live_entry_action(
    request, slug: str, entry_id: int, action: Literal["up", "down", "remove", "restart"]
):
    """Move a waiting racer ``up`` or ``down``, take one out (``remove``), or put one whose turn
    ended back at the head (``restart``): facilitators."""
    event = _facilitated(request, slug)
    session = _session(event)
    entry = session.entries.filter(pk=entry_id).first()
    if entry is None:
        raise ApiError(404, "not_found", f"No place in this queue has the id {entry_id}.")
    if action in ACTIONS:
        _refused_as_conflict(live_races.live_entry_move, entry=entry, places=ACTIONS[action])
    elif action == "remove":
        _refused_as_conflict(live_races.live_entry_remove, entry=entry)
    else:
        _refused_as_conflict(live_races.live_entry_restart, entry=entry)
    return broadcasts.queue_state(session)


@router.post("/{slug}/live/launch", response={200: Queue, **REFUSED})
def live_launch(request, slug: str):
    """Launch the next turn: the first waiting racer's car on the track (facilitators)."""
    session = _session(_facilitated(request, slug))
    _refused_as_conflict(live_races.live_turn_launch, session=session)
    return broadcasts.queue_state(session)


@router.post("/{slug}/winner", response={200: Winner, **REFUSED})
def winner_show(request, slug: str, body: WinnerIn):
    """Show the event's winner on its broadcast, or hide it (``show``: false): its live race's
    facilitator, or a physical event's timekeeper."""
    event = event_of(request, slug)
    user = request.user
    runs = (
        timing.may_keep_time(event=event, user=user)
        if event.physical
        else live_races.may_facilitate(event=event, user=user)
    )
    if not runs:
        raise ApiError(404, "not_found", f"No event you run is called {slug!r}.")
    _need_to_run(request, event)
    winner = services.event_winner_show(event=event, shown=body.show)
    if body.show and winner is None:
        raise ApiError(409, "refused", "Nobody is ranked yet: there is no winner to show.")
    return {"shown": body.show, "winner": winner}


def _session(event: Event, opened: bool = True) -> LiveSession | None:
    """The event's live session; 409 unless it is open (``opened``: it must be)."""
    session = LiveSession.objects.filter(event=event).first()
    if session is None and opened:
        raise ApiError(409, "not_open", f"{event.name} has no live session open.")
    return session


def _facilitated(request, slug: str) -> Event:
    """The event, when this request may run its live race; 404 otherwise (as the pages)."""
    event = event_of(request, slug)
    if not live_races.may_facilitate(event=event, user=request.user):
        raise ApiError(404, "not_found", f"No live race you run is called {slug!r}.")
    _need_to_run(request, event)
    return event


def _need_to_run(request, event: Event) -> None:
    """An organiser runs their own race with ``race``; staff run any with ``admin``."""
    need(request, TokenScope.RACE if event.organiser_id == request.user.pk else TokenScope.ADMIN)


def _refused_as_conflict(action, **arguments) -> None:
    try:
        action(**arguments)
    except live_races.LiveRefused as refused:
        raise ApiError(409, "refused", str(refused)) from None


def _entry_out(session: LiveSession, entry_id: int) -> dict:
    state = broadcasts.queue_state(session)
    return next(row for row in [*state["entries"], *state["cars"]] if row["id"] == entry_id)
