"""The league in the API: the events a racer may see, an event's leaderboard, submitting a model
to an event, and the racer's own runs with their laps.

The league pages' rules, through their selectors and services: a community race is seen by its
organiser, its participants and staff alone (404 for anyone else); a submission is checked as the
submit page checks it (``submission_refusal``: the event open, the racer's division, the
invitation, the limit per racer) and counted against the racer's ``evaluate`` limit.
"""

from __future__ import annotations

from datetime import date, datetime

from ninja import Query, Router, Schema, Status

from accounts.models import TokenScope
from accounts.selectors import racer_name
from api.auth import need
from api.errors import ApiError, counted
from api.owned import own_model
from api.schemas import REFUSED
from racing import selectors, services
from racing.models import Division, Event, Season, Submission

router = Router()


class EventOut(Schema):
    slug: str
    name: str
    season: str
    division: str
    track: str
    race_type: str
    state: str
    opens_at: datetime
    closes_at: datetime
    ranking_method: str
    laps_required: int
    laps_to_drive: int
    off_track_penalty_s: float
    crash_penalty_s: float
    submissions_per_racer: int
    physical: bool
    public: bool


class RankingOut(Schema):
    position: int
    racer: str
    model_name: str
    score_ms: int
    gap_ms: int
    laps_completed: int
    off_tracks: int
    submitted_at: datetime


class Leaderboard(Schema):
    event: str
    page: int
    pages: int
    count: int
    items: list[RankingOut]


class LapOut(Schema):
    number: int
    time_ms: int
    status: str
    counted: bool
    off_tracks: int
    crashes: int
    resets: int
    penalty_ms: int


class SubmissionOut(Schema):
    id: int
    event: str
    model: int | None
    model_name: str
    status: str
    checkpoint: str
    score_ms: int | None
    qualified: bool
    laps_completed: int
    off_tracks: int
    disqualified: bool
    failure_reason: str
    created_at: datetime
    finished_at: datetime | None


class SubmissionDetail(SubmissionOut):
    laps: list[LapOut]


class SubmitIn(Schema):
    model: int
    checkpoint: str = "best"


class SeasonOut(Schema):
    name: str
    year: int
    starts_on: date
    ends_on: date
    events: list[str]  # the slugs of its public events


class StandingOut(Schema):
    position: int
    racer: str
    points: int
    finishes: list[int]  # its places in the events counted, best first


class Standings(Schema):
    season: str
    division: str
    events: list[str]
    standings: list[StandingOut]


@router.get("/seasons", response={200: list[SeasonOut], **REFUSED})
def seasons_list(request):
    """The league's seasons, newest first, with their public events."""
    need(request, TokenScope.READ)
    return [
        {
            **{f: getattr(s, f) for f in ("name", "year", "starts_on", "ends_on")},
            "events": [event.slug for event in s.events.all()],
        }
        for s in selectors.seasons_with_events()
    ]


@router.get("/seasons/{name}/standings", response={200: Standings, **REFUSED})
def season_standings(request, name: str, division: Division = Division.OPEN):
    """A season's standings in a division, as its page ranks them: each event's first ten
    places score Formula 1's points; ties are broken by countback."""
    need(request, TokenScope.READ)
    season = Season.objects.filter(name=name).first()
    if season is None:
        raise ApiError(404, "not_found", f"No season is called {name!r}.")
    standings, events = selectors.season_standings(season=season, division=division)
    return {
        "season": season.name,
        "division": division,
        "events": [event.slug for event in events],
        "standings": [
            {
                "position": s.position,
                "racer": racer_name(racer=s.racer),
                "points": s.points,
                "finishes": s.finishes,
            }
            for s in standings
        ],
    }


def _event_out(event: Event) -> dict:
    return {
        **{name: getattr(event, name) for name in EventOut.model_fields if name != "season"},
        "season": event.season.name,
        "track": event.track.name,
        "state": event.state,
    }


def event_of(request, slug: str) -> Event:
    event = selectors.events_visible_to(user=request.user).filter(slug=slug).first()
    if event is None:
        raise ApiError(404, "not_found", f"No event you may see is called {slug!r}.")
    return event


def _submission_out(submission: Submission) -> dict:
    return {
        **{name: getattr(submission, name) for name in SubmissionOut.model_fields},
        "event": submission.event.slug,
        "model": submission.model_id,
    }


@router.get("/events", response={200: list[EventOut], **REFUSED})
def events_list(request):
    """The events you may see, newest first: the league's, and the community races you organise
    or joined."""
    need(request, TokenScope.READ)
    return [
        _event_out(event)
        for event in selectors.events_visible_to(user=request.user).order_by("-opens_at")
    ]


@router.get("/events/{slug}", response={200: EventOut, **REFUSED})
def event_detail(request, slug: str):
    """One event and its rules."""
    need(request, TokenScope.READ)
    return _event_out(event_of(request, slug))


@router.get("/events/{slug}/leaderboard", response={200: Leaderboard, **REFUSED})
def event_leaderboard(request, slug: str, page: int = Query(1, ge=1, le=10**6)):
    """The event's leaderboard, as its page ranks it: each place's racer name (never a login
    name), model, score [ms] and gap to first; 50 places a page."""
    need(request, TokenScope.READ)
    event = event_of(request, slug)
    current = selectors.leaderboard_page(event=event, page=page)
    return {
        "event": event.slug,
        "page": current.number,
        "pages": current.paginator.num_pages,
        "count": current.paginator.count,
        "items": [
            {
                "position": ranking.position,
                "racer": racer_name(racer=ranking.racer),
                "model_name": ranking.model_name,
                "score_ms": ranking.score_ms,
                "gap_ms": ranking.gap_ms,
                "laps_completed": ranking.laps_completed,
                "off_tracks": ranking.off_tracks,
                "submitted_at": ranking.submitted_at,
            }
            for ranking in current.object_list
        ],
    }


@router.post("/events/{slug}/submissions", response={201: SubmissionDetail, **REFUSED})
def submission_create(request, slug: str, body: SubmitIn):
    """Submit one of your ready models to the event, as the submit page does: its race is
    queued under the event's rules with the ``best`` or ``last`` checkpoint; what the page
    would refuse answers 409 with its words."""
    need(request, TokenScope.RACE)
    event = event_of(request, slug)
    model = own_model(request, body.model)
    counted(request, "evaluate")
    try:
        submission = services.submission_create(
            racer=request.user, event=event, model=model, checkpoint=body.checkpoint
        )
    except services.SubmissionRefused as refused:
        raise ApiError(409, "refused", str(refused)) from None
    return Status(201, {**_submission_out(submission), "laps": []})


@router.get("/submissions", response={200: list[SubmissionOut], **REFUSED})
def submissions_list(request):
    """Your runs, newest first (200 at most)."""
    need(request, TokenScope.READ)
    runs = selectors.submissions_for_racer(racer=request.user).select_related("event")
    return [_submission_out(submission) for submission in runs[:200]]


@router.get("/submissions/{submission_id}", response={200: SubmissionDetail, **REFUSED})
def submission_detail(request, submission_id: int):
    """One of your runs, with each lap."""
    need(request, TokenScope.READ)
    submission = (
        Submission.objects.select_related("event")
        .filter(pk=submission_id, racer=request.user)
        .first()
    )
    if submission is None:
        raise ApiError(404, "not_found", f"No run of yours has the id {submission_id}.")
    return {**_submission_out(submission), "laps": list(submission.laps.order_by("number"))}
