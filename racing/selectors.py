"""Reads for the league."""

from __future__ import annotations

from dataclasses import dataclass, field

from django.contrib.auth.models import AbstractBaseUser
from django.core.paginator import Page, Paginator
from django.db.models import Count, Min, Prefetch, Q, QuerySet
from django.utils import timezone

from accounts.selectors import racer_name
from common.time_zones import local_text
from racing.models import (
    RANKING_ORDER,
    Division,
    Event,
    Racer,
    Ranking,
    Season,
    Submission,
)
from training import selectors as training_selectors
from training.models import RLModel, TrainingJob

LEADERBOARD_PAGE = 100  # rankings per page
# Season points by place in an event, 1st to 10th (Formula 1's table); lower places score none.
POINTS = (25, 18, 15, 12, 10, 8, 6, 4, 2, 1)


def seasons_with_events() -> QuerySet[Season]:
    return Season.objects.prefetch_related(
        Prefetch("events", queryset=public_events().select_related("track"))
    )


def public_events() -> QuerySet[Event]:
    return Event.objects.filter(public=True)


def events_with_leaders() -> QuerySet[Event]:
    return (
        public_events()
        .select_related("season", "track")
        .annotate(entries=Count("rankings"), best_ms=Min("rankings__score_ms"))
    )


def events_not_closed() -> QuerySet[Event]:
    """Open and upcoming public events, soonest first."""
    return events_with_leaders().filter(closes_at__gt=timezone.now())


def events_visible_to(*, user: AbstractBaseUser) -> QuerySet[Event]:
    """The events ``user`` may see (``event_visible_to``'s rule, as a query): the public ones,
    and the community races they organise or joined; league staff see every one."""
    events = Event.objects.select_related("season", "track")
    if user.is_staff:
        return events
    mine = Q(public=True) | Q(organiser=user) | Q(participants=user)
    return events.filter(mine).distinct()


def event_visible_to(*, event: Event, user: AbstractBaseUser) -> bool:
    """Public events are for everyone; a community race for its organiser, its participants
    and league staff."""
    if event.public or user.is_staff:
        return True
    return user.is_authenticated and (
        event.organiser_id == user.pk or event.participants.filter(pk=user.pk).exists()
    )


def submission_visible_to(*, submission: Submission, user: AbstractBaseUser) -> bool:
    """A run's page and video are for its racer and staff, and for everyone who may see its
    event once the run stands on the leaderboard (as the racer's best)."""
    if user.is_authenticated and (user.pk == submission.racer_id or user.is_staff):
        return True
    return (
        event_visible_to(event=submission.event, user=user)
        and Ranking.objects.filter(submission=submission).exists()
    )


# Leaderboards


def leaderboard_page(*, event: Event, page: int | str = 1) -> Page:
    """One page of the event's rankings in order, each with its ``position`` and ``gap_ms`` to
    first. An out-of-range page number gives the last page."""
    rankings = event.rankings.select_related("racer__profile", "submission")
    rankings = rankings.order_by(*RANKING_ORDER)
    current = Paginator(rankings, LEADERBOARD_PAGE).get_page(page)
    current.object_list = list(current.object_list)
    leader = current.object_list[0] if current.number == 1 and current.object_list else None
    best = leader.score_ms if leader else rankings.values_list("score_ms", flat=True).first()
    for offset, ranking in enumerate(current.object_list):
        ranking.position = current.start_index() + offset
        ranking.gap_ms = ranking.score_ms - best
    return current


def leaders(*, event: Event, count: int) -> list[Ranking]:
    """The event's first ``count`` rankings, in order."""
    rankings = event.rankings.select_related("racer__profile", "submission")
    return list(rankings.order_by(*RANKING_ORDER)[:count])


def top_entries(*, event: Event, count: int) -> list[dict]:
    """The event's first ``count`` places as the broadcast shows them (JSON)."""
    return [
        {
            "place": place,
            "racer": racer_name(racer=ranking.racer),
            "model_name": ranking.model_name,
            "score_ms": ranking.score_ms,
            "physical": ranking.submission.physical,
        }
        for place, ranking in enumerate(leaders(event=event, count=count), start=1)
    ]


def winner_shown(*, event: Event) -> dict | None:
    """The winner the broadcast shows: the leader now, once the organiser has shown the winner
    (``Event.winner_shown_at``); None before, or with nobody ranked."""
    if event.winner_shown_at is None:
        return None
    return next(iter(top_entries(event=event, count=1)), None)


def rivals_for(*, event: Event, racer: AbstractBaseUser) -> list[Submission]:
    """What a submission to ``event`` races against when the event puts several cars on the
    track (``Event.cars``): the ranked submissions of the leaders other than ``racer``, best
    first, one fewer than the cars, whose models are still here with trained weights (a
    deleted leader's place goes to the next). None in a race of one car."""
    found: list[Submission] = []
    if event.cars < 2:
        return found
    rankings = event.rankings.exclude(racer=racer).select_related("submission__model")
    for ranking in rankings.order_by(*RANKING_ORDER).iterator(chunk_size=50):
        model = ranking.submission.model
        if model is None or model.status in (RLModel.Status.DELETING, RLModel.Status.ERROR):
            continue
        which = ranking.submission.checkpoint
        if training_selectors.model_checkpoint(model=model, which=which) is None:
            continue
        found.append(ranking.submission)
        if len(found) == event.cars - 1:
            break
    return found


def ranking_of(*, event: Event, racer: AbstractBaseUser) -> Ranking | None:
    """The racer's ranking in the event with its ``position`` (None when they are not ranked)."""
    if not racer.is_authenticated:
        return None
    ranking = (
        Ranking.objects.filter(event=event, racer=racer).select_related("racer__profile").first()
    )
    if ranking is None:
        return None
    ahead = event.rankings.filter(
        Q(score_ms__lt=ranking.score_ms)
        | Q(score_ms=ranking.score_ms, submitted_at__lt=ranking.submitted_at)
        | Q(score_ms=ranking.score_ms, submitted_at=ranking.submitted_at, id__lt=ranking.pk)
    ).count()
    ranking.position = ahead + 1
    ranking.page = ahead // LEADERBOARD_PAGE + 1
    return ranking


# Season standings


@dataclass
class Standing:
    racer: AbstractBaseUser  # its profile fetched with it
    points: int = 0
    finishes: list[int] = field(default_factory=list)  # places, best first
    position: int = 0

    @property
    def best(self) -> int:
        return self.finishes[0]


def season_standings(*, season: Season, division: str) -> tuple[list[Standing], list[Event]]:
    """The season's standings in one division, and the events they count: every public event
    of that division that has opened. Each event gives its first ten places ``POINTS``; racers
    are ordered by points, then by countback (more first places, then more second places, and
    so on), then by racer name."""
    events = list(
        season.events.filter(public=True, division=division, opens_at__lte=timezone.now())
        .select_related("track")
        .order_by("opens_at", "name")
    )
    standings: dict[int, Standing] = {}
    for event in events:
        top = event.rankings.select_related("racer__profile").order_by(*RANKING_ORDER)
        for place, ranking in enumerate(top[: len(POINTS)], start=1):
            standing = standings.setdefault(ranking.racer_id, Standing(ranking.racer))
            standing.points += POINTS[place - 1]
            standing.finishes.append(place)
    ordered = sorted(
        standings.values(),
        key=lambda s: (-s.points, sorted(s.finishes), racer_name(racer=s.racer).lower()),
    )
    for position, standing in enumerate(ordered, start=1):
        standing.finishes.sort()
        standing.position = position
    return ordered, events


# Submitting


def submission_refusal(
    *, racer: AbstractBaseUser, event: Event, model: RLModel | None
) -> str | None:
    """Why ``racer`` cannot submit ``model`` to ``event`` now, in words for them; None if they
    can (the model's own state is checked when the race is reserved)."""
    if model is not None and model.owner_id != racer.pk:
        return "You can submit only your own models."
    if event.physical:
        return f"{event.name} is raced by real cars: its timekeeper times each car at the track."
    state = event.state
    if state == Event.State.UPCOMING:
        return f"{event.name} opens on {local_text(event.opens_at)}; submit then."
    if state == Event.State.CLOSED:
        return f"{event.name} has closed; it takes no more submissions."
    if not event.public:
        joined = event.participants.filter(pk=racer.pk).exists()
        if not joined:
            return "This is a private race: join it through its invitation link first."
    elif not event.any_division:
        division = Racer.of(racer).division
        if division != event.division:
            return (
                f"{event.name} is a {event.get_division_display()} event and you race in the "
                f"{Division(division).label} division. "
                + (
                    "Place in the top 10% of a month's Open time trials to move up to Pro."
                    if division == Division.OPEN
                    else "Pro racers enter Pro events."
                )
            )
    used = submissions_counted(racer=racer, event=event)
    if used >= event.submissions_per_racer:
        return (
            f"You have made your {event.submissions_per_racer} submissions to {event.name}, "
            "its limit."
        )
    return None


def submissions_counted(*, racer: AbstractBaseUser, event: Event) -> int:
    """Submissions that count against the event's limit: all but those that failed (a failure
    is ours, not the racer's)."""
    return (
        Submission.objects.filter(racer=racer, event=event)
        .exclude(status=Submission.Status.FAILED)
        .count()
    )


def events_open_to(*, racer: AbstractBaseUser) -> list[Event]:
    """The open events ``racer`` may enter now: public ones of their division or open to both,
    and community races they joined."""
    now = timezone.now()
    division = Racer.of(racer).division
    public = Q(public=True) & (Q(division=division) | Q(any_division=True))
    return list(
        Event.objects.filter(opens_at__lte=now, closes_at__gt=now, physical=False)
        .filter(public | Q(public=False, participants=racer))
        .select_related("track", "season")
        .distinct()
        .order_by("closes_at", "name")
    )


def models_ready_for(*, racer: AbstractBaseUser) -> QuerySet[RLModel]:
    """The racer's ready models by name, each with ``saved_jobs``: its trainings that saved a
    checkpoint, newest first (one query for all, for ``model_untrained``'s last checkpoint)."""
    saved = TrainingJob.objects.exclude(last_checkpoint="").order_by("-created_at")
    return (
        RLModel.objects.filter(owner=racer, status=RLModel.Status.READY)
        .order_by("name")
        .prefetch_related(Prefetch("jobs", queryset=saved, to_attr="saved_jobs"))
    )


def submissions_for_racer(*, racer: AbstractBaseUser) -> QuerySet[Submission]:
    return Submission.objects.filter(racer=racer).select_related("event", "event__track")


def submissions_in_event(*, event: Event, racer: AbstractBaseUser) -> list[Submission]:
    """The racer's own runs in the event, newest first: qualified or not, what the leaderboard
    shows them beside the rankings (nothing for a visitor)."""
    if not racer.is_authenticated:
        return []
    return list(submissions_for_racer(racer=racer).filter(event=event).order_by("-created_at"))


def invitation_refusal(*, event: Event, racer: AbstractBaseUser) -> str | None:
    """Why the racer cannot join the community race through its invitation; None if they can."""
    if event.state == Event.State.CLOSED:
        return "This invitation expired when the race closed."
    if racer.is_authenticated and event.removed.filter(pk=racer.pk).exists():
        organiser = racer_name(racer=event.organiser)
        return (
            f"{organiser} took you out of {event.name}, so its invitation no longer lets "
            f"you in. If you think that was a mistake, ask {organiser} to let you back in."
        )
    return None


def race_deletion_refusal(*, event: Event) -> str | None:
    """Why the organiser cannot delete their community race; None if they can (nobody has
    submitted to it yet)."""
    runs = event.submissions.count()
    if not runs:
        return None
    return (
        f"{event.name} has {runs} submission{'s' if runs != 1 else ''}, so it stays: its racers' "
        "runs and places are kept. Close it instead if it should take no more."
    )


def community_races_for(*, racer: AbstractBaseUser) -> QuerySet[Event]:
    """Community races the racer organises or joined, newest first."""
    return (
        Event.objects.filter(public=False)
        .filter(Q(organiser=racer) | Q(participants=racer))
        .select_related("track", "organiser__profile")
        .distinct()
        .order_by("-opens_at")
    )
