"""Live races: an event raced turn by turn while everyone watches, as DeepRacer on AWS's Live
Racing and the DeepRacer console's LIVE community races ran them.

The facilitator (staff, or a community race's organiser) opens a live session for a simulated
event. Racers join its queue with a ready model and a speed multiplier within the session's
bounds (the console's LIVE races let racers drive at 0.5-1.5 times their model's speeds). The
facilitator reorders the queue, removes entries, puts a finished racer back at its head to race
again, and launches each turn, or lets the session launch the next one as soon as a turn ends
(autolaunch). A turn is the racer's submission to the event, driven on a simulation worker in
real time (``EvaluationJob.real_time``), its frames on the race page for everyone; it is scored
by the event's rules into its leaderboard, as any submission is. The racer whose turn is next
is told so.
"""

from __future__ import annotations

import contextlib

from django.contrib.auth.models import AbstractBaseUser
from django.db import transaction
from django.db.models import Max

from common.lifecycle import Lifecycle
from common.refusals import Refused
from notifications import services as notifications
from racing import broadcasts, selectors, services
from racing.models import Event, LiveEntry, LiveSession, Submission
from training.models import RLModel

_L = LiveEntry.Status
# A queue entry's status and its moves (see training.lifecycle): it waits, drives its turn, is
# done; a facilitator takes a waiting one out, and puts one that is done or out back to wait.
LIVE_ENTRY = Lifecycle(
    LiveEntry,
    {
        _L.WAITING: frozenset({_L.DRIVING, _L.REMOVED}),
        _L.DRIVING: frozenset({_L.DONE}),
        _L.DONE: frozenset({_L.WAITING}),
        _L.REMOVED: frozenset({_L.WAITING}),
    },
    born=frozenset({_L.WAITING}),
)


class LiveRefused(Refused):
    """The live session cannot do that now; the message says why."""


def may_facilitate(*, event: Event, user: AbstractBaseUser) -> bool:
    """Staff run any simulated event's live session; a community race's organiser runs theirs."""
    if not user.is_authenticated or event.physical:
        return False
    if user.is_staff:
        return selectors.event_visible_to(event=event, user=user)
    return event.organiser_id == user.pk


def live_session_open(
    *,
    event: Event,
    facilitator: AbstractBaseUser,
    min_speed: float = 0.5,
    max_speed: float = 1.5,
    autolaunch: bool = False,
) -> LiveSession:
    """The event's live session, opened (or its settings changed)."""
    if event.physical:
        raise LiveRefused(f"{event.name} is raced by real cars: its timekeeper times them.")
    if event.state == Event.State.CLOSED:
        raise LiveRefused(f"{event.name} has closed: it cannot be raced live.")
    if not 0.1 <= min_speed <= max_speed <= 2.0:
        raise LiveRefused("The speed multipliers run from 0.1 to 2.0, the slowest first.")
    session, _ = LiveSession.objects.update_or_create(
        event=event,
        defaults={
            "facilitator": facilitator,
            "min_speed": min_speed,
            "max_speed": max_speed,
            "autolaunch": autolaunch,
        },
    )
    broadcasts.announce_queue(session)
    return session


def live_entry_join(
    *, session: LiveSession, racer: AbstractBaseUser, model: RLModel, speed: float = 1.0
) -> LiveEntry:
    """``racer`` joins the queue with ``model`` at ``speed`` times its speeds."""
    if not session.min_speed <= speed <= session.max_speed:
        raise LiveRefused(
            f"Choose a speed multiplier from {session.min_speed:g} to {session.max_speed:g}."
        )
    reason = selectors.submission_refusal(racer=racer, event=session.event, model=model)
    if reason:
        raise LiveRefused(reason)
    if model.status != RLModel.Status.READY:
        raise LiveRefused(
            f"{model.name} is {model.get_status_display().lower()}: join with it once it is ready."
        )
    with transaction.atomic():
        LiveSession.objects.select_for_update().filter(pk=session.pk).first()
        if live_place_held(session=session, racer=racer):
            raise LiveRefused("You are in the queue already: one place a racer.")
        last = session.entries.aggregate(last=Max("position"))["last"] or 0
        entry = LiveEntry.objects.create(
            session=session,
            racer=racer,
            model=model,
            model_name=model.name,
            speed=speed,
            position=last + 1,
        )
    broadcasts.announce_queue(session)
    return entry


def live_place_held(*, session: LiveSession, racer: AbstractBaseUser) -> bool:
    """Whether ``racer`` has a place in the queue or a car on the track: one place a racer."""
    if not racer.is_authenticated:
        return False
    held = session.entries.filter(racer=racer, status__in=(_L.WAITING, _L.DRIVING))
    return held.exists()


def live_entry_move(*, entry: LiveEntry, places: int) -> LiveEntry:
    """Move a waiting entry ``places`` up (negative) or down the queue."""
    with transaction.atomic():
        waiting = list(_waiting(entry.session, lock=True))
        index = next((i for i, e in enumerate(waiting) if e.pk == entry.pk), None)
        if index is None:
            raise LiveRefused("Only a racer still waiting can be moved.")
        moved = waiting.pop(index)
        waiting.insert(max(0, min(len(waiting), index + places)), moved)
        _number(waiting)
    broadcasts.announce_queue(entry.session)
    return moved


def live_entry_remove(*, entry: LiveEntry) -> None:
    """Take a waiting racer out of the queue."""
    if not LIVE_ENTRY.move(entry, _L.REMOVED, only_from=frozenset({_L.WAITING})):
        raise LiveRefused("Only a racer still waiting can be taken out: a turn drives to its end.")
    broadcasts.announce_queue(entry.session)


def live_entry_restart(*, entry: LiveEntry) -> LiveEntry:
    """A racer whose turn ended (or who was taken out) races again: back at the queue's head."""
    with transaction.atomic():
        waiting = list(_waiting(entry.session, lock=True))
        again = frozenset({_L.DONE, _L.REMOVED})
        if not LIVE_ENTRY.move(entry, _L.WAITING, only_from=again, submission=None):
            raise LiveRefused("Only a racer whose turn has ended can race again.")
        _number([entry, *waiting])
    broadcasts.announce_queue(entry.session)
    return entry


def live_turn_launch(*, session: LiveSession) -> LiveEntry:
    """The next turn: the first waiting racer's submission, queued to drive in real time, with
    the racers after them on the grid behind where the event puts several cars on the track
    (``Event.cars``: fewer when fewer wait); its first entry."""
    with transaction.atomic():
        session = LiveSession.objects.select_for_update().select_related("event").get(pk=session.pk)
        if session.entries.filter(status=_L.DRIVING).exists():
            raise LiveRefused("A turn is driving: launch the next when it ends.")
        entries = list(_waiting(session)[: session.event.cars])
        if not entries:
            raise LiveRefused("Nobody is waiting: racers join the queue from the race page.")
        leader = None
        for position, entry in enumerate(entries):
            if entry.model is None:
                raise LiveRefused(f"{entry.model_name} was deleted: take it out of the queue.")
            try:
                submission = services.submission_create(
                    racer=entry.racer,
                    event=session.event,
                    model=entry.model,
                    speed_multiplier=entry.speed,
                    real_time=True,
                    against_leaders=False,
                    grid_leader=leader,
                    grid_position=position,
                )
            except services.SubmissionRefused as refused:
                raise LiveRefused(f"{entry.model_name} cannot race now: {refused}") from None
            leader = leader or submission.evaluation
            LIVE_ENTRY.move(entry, _L.DRIVING, submission=submission)
        following = _waiting(session).select_related("session__event").first()
    broadcasts.announce_queue(session)
    if following is not None:
        notifications.live_turn_next(entry=following)
    return entries[0]


def live_turn_ended(*, submission: Submission) -> None:
    """A live turn's submission was scored or failed: its entry is done, and with autolaunch the
    next racer's turn begins (a racer whose model cannot race now is skipped and stays waiting
    for the facilitator)."""
    entry = LiveEntry.objects.select_related("session__event").filter(submission=submission).first()
    if entry is None:
        return
    LIVE_ENTRY.move(entry, _L.DONE)
    session = entry.session
    broadcasts.announce_queue(session)
    if session.autolaunch and _waiting(session).exists():
        with contextlib.suppress(LiveRefused):  # the facilitator sees the queue and decides
            live_turn_launch(session=session)


def _waiting(session: LiveSession, *, lock: bool = False):
    entries = session.entries.filter(status=_L.WAITING).order_by("position", "pk")
    return entries.select_for_update() if lock else entries


def _number(entries: list[LiveEntry]) -> None:
    for position, entry in enumerate(entries, start=1):
        if entry.position != position:
            LiveEntry.objects.filter(pk=entry.pk).update(position=position)
            entry.position = position
