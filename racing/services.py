"""Writes for the league: submissions and their scores, rankings, events, divisions.

Long because the league's writes are kept in one module, as HackSoft's styleguide keeps an
app's services: entering a race, scoring its laps, ranking, the monthly promotion and the race
staff's actions call one another, and a reader follows a submission through them in order.
"""

from __future__ import annotations

import calendar
import enum
import logging
import math
from datetime import date, datetime, time, timedelta

from django.contrib.auth import get_user_model
from django.contrib.auth.models import AbstractBaseUser
from django.core.exceptions import ValidationError
from django.core.files.storage import default_storage
from django.db import IntegrityError, transaction
from django.utils import timezone
from django.utils.crypto import get_random_string
from django.utils.text import slugify

from common import queueing
from common.lifecycle import Lifecycle
from common.refusals import Refused
from common.transactions import outside_transaction
from notifications import services as notifications
from racing import broadcasts, scoring, selectors
from racing.models import (
    RANKING_ORDER,
    Division,
    Event,
    Lap,
    Racer,
    RaceType,
    Ranking,
    Season,
    Submission,
)
from training import services as training_services
from training.models import EvaluationJob, EvaluationTrial, RLModel, Track

logger = logging.getLogger(__name__)

RACE = "racing.race"  # the task that drives a submission's race (racing.tasks), queued by name

_S = Submission.Status
# A race entry's status and its moves (see training.lifecycle): every write of it is a move.
SUBMISSION = Lifecycle(
    Submission,
    {
        # The race task drives it (a redelivered task drives an interrupted one again), then
        # scores it; scoring the same laps again changes nothing.
        _S.QUEUED: frozenset({_S.IN_PROGRESS}),
        _S.IN_PROGRESS: frozenset({_S.COMPLETED, _S.FAILED}),
        _S.COMPLETED: frozenset(),
        _S.FAILED: frozenset(),
        # A training job's statuses a race entry never takes.
        _S.INITIALIZING: frozenset(),
        _S.STOPPING: frozenset(),
        _S.CANCELED: frozenset(),
    },
    born=frozenset({_S.QUEUED}),
)

PROMOTED_SHARE = 0.10  # the top 10% of a month's Open time trials move up to Pro
RESUBMIT_WINDOW = timedelta(minutes=10)  # a community race made again this soon is the same
VIDEO = "video.webm"


class SubmissionRefused(Refused):
    """The racer cannot submit this model to this event; the message says why."""


# Submitting and scoring


def submission_create(
    *,
    racer: AbstractBaseUser,
    event: Event,
    model: RLModel,
    checkpoint: str = "best",
    speed_multiplier: float = 1.0,
    real_time: bool = False,
    grid_leader: EvaluationJob | None = None,
    grid_position: int = 0,
    against_leaders: bool = True,
) -> Submission:
    """Enter ``model`` in ``event`` with its ``checkpoint`` ("best" or "last"): checked
    (``SubmissionRefused`` says why not), then a race evaluation under the event's rules is
    queued, with a seed of its own that the submission keeps, and the model is SUBMITTING until
    it ends. The racer's row is locked meanwhile, so two submissions at once cannot overrun the
    limit. A live race's turn drives at ``speed_multiplier`` times the model's speeds, in
    ``real_time`` (racing.live_races). Where the event puts several cars on the track
    (``Event.cars``), the model races ``against_leaders``' models (``selectors.rivals_for``),
    or, with ``grid_leader``, it is car ``grid_position`` of that evaluation's race (a live
    turn's next racers), driven by that race's run rather than a task of its own."""
    if checkpoint not in EvaluationJob.Checkpoint.values:
        raise SubmissionRefused("Race the model's best or its last checkpoint.")
    with transaction.atomic():
        _lock(racer)
        if _lock_event(event) is None:
            raise SubmissionRefused(f"{event.name} was deleted by its organiser.")
        reason = selectors.submission_refusal(racer=racer, event=event, model=model)
        if reason:
            raise SubmissionRefused(reason)
        try:
            evaluation = training_services.evaluation_reserve(
                model=model,
                purpose=RLModel.Status.SUBMITTING,
                **race_rules(event, checkpoint=checkpoint),
                speed_multiplier=speed_multiplier,
                real_time=real_time,
                grid_leader=grid_leader,
                grid_position=grid_position,
            )
        except training_services.EvaluationRefused as refused:
            raise SubmissionRefused(str(refused)) from None
        submission = Submission.objects.create(
            event=event,
            racer=racer,
            model=model,
            model_name=model.name,
            evaluation=evaluation,
            checkpoint=checkpoint,
            seed=evaluation.seed,
        )
        if grid_leader is not None:
            return submission  # its race's first car's run drives it, and scores it
        if against_leaders:
            _rivals_add(evaluation, event=event, racer=racer)
        # A send that fails (the broker unreachable) is logged, not the racer's error: the
        # workers send a queued task that is not in the broker again (console.recovery).
        transaction.on_commit(lambda: queueing.enqueue(RACE, submission.pk), robust=True)
    return submission


def _rivals_add(evaluation: EvaluationJob, *, event: Event, racer: AbstractBaseUser) -> None:
    """Behind ``evaluation`` on the grid, the leaders' models (``selectors.rivals_for``)."""
    for position, rival in enumerate(selectors.rivals_for(event=event, racer=racer), start=1):
        training_services.evaluation_rival_add(
            leader=evaluation,
            model=rival.model,
            position=position,
            **race_rules(event, checkpoint=rival.checkpoint),
        )


def race_rules(event: Event, *, checkpoint: str = "best") -> dict:
    """The evaluation a submission to ``event`` drives: its track and race, its laps one after
    another, its penalties, the model's ``checkpoint`` (best or last)."""
    return {
        "track": event.track,
        "direction": event.direction,
        "race_type": event.race_type,
        "boxes": event.boxes,
        "bots": event.bots,
        "trials": event.laps_to_drive,
        "continuous_laps": True,
        "off_track_penalty": event.off_track_penalty_s,
        "crash_penalty": event.crash_penalty_s,
        "checkpoint": checkpoint,
    }


def submission_run(*, submission_id: int) -> Submission | None:
    """The ``racing.race`` task's work: drive the submission's evaluation, then score it. A
    redelivered task drives an interrupted evaluation again and scores a finished one; a
    submission that has ended or vanished is left alone (None)."""
    from jobs import evaluation as evaluations

    submission = Submission.objects.select_related("event").filter(pk=submission_id).first()
    if submission is None or not submission.is_active:
        logger.info("Submission %s is not waiting; nothing to do", submission_id)
        return None
    race = [submission]  # with the submissions racing with it (a live turn's next racers)
    if submission.evaluation_id is not None:
        race += (
            Submission.objects.select_related("event")
            .filter(evaluation__grid_leader=submission.evaluation_id, status__in=Submission.ACTIVE)
            .order_by("evaluation__grid_position")
        )
    for entry in race:
        SUBMISSION.move(entry, Submission.Status.IN_PROGRESS)
        broadcasts.announce_submission(entry)
    if submission.evaluation_id is not None:
        evaluations.run(submission.evaluation_id)
    for entry in race[1:]:
        _conclude(entry)
    return _conclude(submission)


def _conclude(submission: Submission) -> Submission | None:
    """Once its evaluation has driven: score the submission, or fail it with the reason; None
    while another run drives its evaluation (that run scores it)."""
    evaluation = EvaluationJob.objects.filter(pk=submission.evaluation_id).first()
    if evaluation is not None and evaluation.is_active:
        logger.info("Submission %s is raced by another run", submission.pk)
        return None  # a duplicate delivery: the run holding the evaluation's lease scores it
    if evaluation is None or evaluation.status != EvaluationJob.Status.COMPLETED:
        reason = (evaluation.failure_reason if evaluation else "") or "The race did not finish."
        SUBMISSION.move(
            submission, Submission.Status.FAILED, failure_reason=reason, finished_at=timezone.now()
        )
        broadcasts.announce_submission(submission)
        _live_turn_ended(submission)
        return submission
    Submission.objects.filter(pk=submission.pk).update(
        checkpoint_iteration=evaluation.checkpoint_iteration
    )  # the weights that raced, kept when the evaluation goes with its model
    submission.checkpoint_iteration = evaluation.checkpoint_iteration
    submission_score(
        submission=submission,
        trials=list(evaluation.trial_rows.all()),
        video=evaluation.video,
    )
    _live_turn_ended(submission)
    return submission


def _live_turn_ended(submission: Submission) -> None:
    """A live race's turn has ended, scored or failed: its session moves on."""
    from racing import live_races  # it enters races through this module's submission_create

    live_races.live_turn_ended(submission=submission)


def submission_score(
    *, submission: Submission, trials: list[EvaluationTrial], video: str = ""
) -> Submission:
    """Store the laps the race drove, score them by the event's rules, keep the video, and offer
    the score to the racer's ranking. Scoring the same laps again changes nothing."""
    event = submission.event
    laps = [_lap(submission, trial, event) for trial in trials]
    score = scoring.score(
        [lap.scoring_lap() for lap in laps], method=event.ranking_method, size=event.laps_required
    )
    video_name = _keep_video(submission, video)
    with transaction.atomic():
        submission.laps.all().delete()
        Lap.objects.bulk_create(laps)
        SUBMISSION.move(
            submission,
            Submission.Status.COMPLETED,
            finished_at=submission.finished_at or timezone.now(),
            score_ms=score,
            qualified=score is not None,
            laps_completed=sum(lap.status == "lap_complete" for lap in laps),
            off_tracks=sum(lap.off_tracks for lap in laps),
            video=video_name,
        )
        ranked = ranking_offer(submission=submission)
    broadcasts.announce_submission(submission, ranked=ranked)
    notifications.submission_scored(submission=submission)
    return submission


def _lap(submission: Submission, trial: EvaluationTrial, event: Event) -> Lap:
    """A lap counts when the car finished it within the event's off-track limit."""
    return Lap(
        submission=submission,
        number=trial.number,
        time_ms=trial.time_ms,
        status=trial.status,
        off_tracks=trial.off_tracks,
        crashes=trial.crashes,
        resets=trial.resets,
        penalty_ms=trial.penalty_ms,
        counted=trial.completed and event.lap_counts(off_tracks=trial.off_tracks),
    )


def _keep_video(submission: Submission, video: str) -> str:
    """A copy of the race's video under the league's prefix: the leaderboard shows it after the
    model (and its evaluations) are deleted."""
    if not video or not default_storage.exists(video):
        return ""
    outside_transaction("A race's video copied in storage")
    name = f"league/submissions/{submission.pk}/{VIDEO}"
    if default_storage.exists(name):
        default_storage.delete(name)
    with default_storage.open(video, "rb") as source:
        return default_storage.save(name, source)


def _update(submission: Submission, **fields) -> None:
    """Write ``fields`` (not the status: ``SUBMISSION`` moves that); mirror them."""
    Submission.objects.filter(pk=submission.pk).update(**fields)
    for name, value in fields.items():
        setattr(submission, name, value)


# Rankings


def ranking_offer(*, submission: Submission) -> bool:
    """Give the submission's score to its racer's ranking in its event if it is better: a lower
    score, or the same score submitted earlier (ties go to the earlier submission). Under a lock
    on the racer, so scorings that finish together cannot overwrite one another. Whether the
    ranking changed."""
    if submission.ranked_score is None:
        return False
    with transaction.atomic():
        _lock(submission.racer)
        ranking = Ranking.objects.filter(event=submission.event, racer=submission.racer).first()
        if ranking is not None and _order(ranking) <= (
            submission.score_ms,
            submission.created_at,
            submission.pk,
        ):
            return False
        _rank(submission, ranking)
    return True


def _lock(racer: AbstractBaseUser) -> None:
    """Within a transaction: hold the racer's league row until it ends (their submissions and
    ranking change one transaction at a time)."""
    Racer.objects.select_for_update().filter(pk=Racer.of(racer).pk).first()


def _lock_event(event: Event) -> Event | None:
    """Within a transaction: hold the event's row until it ends; None when it is gone. A
    submission is made, and a community race deleted, under this lock, so that a deletion never
    takes with it a submission that arrived after it looked."""
    return Event.objects.select_for_update().filter(pk=event.pk).first()


def _order(ranking: Ranking) -> tuple:
    return ranking.score_ms, ranking.submitted_at, ranking.submission_id


def _rank(submission: Submission, ranking: Ranking | None) -> Ranking:
    fields = {
        "submission": submission,
        "model_name": submission.model_name,
        "score_ms": submission.score_ms,
        "submitted_at": submission.created_at,
        "laps_completed": submission.laps_completed,
        "off_tracks": submission.off_tracks,
    }
    if ranking is None:
        return Ranking.objects.create(event=submission.event, racer=submission.racer, **fields)
    for name, value in fields.items():
        setattr(ranking, name, value)
    ranking.save(update_fields=list(fields))
    return ranking


def ranking_recompute(*, event: Event, racer: AbstractBaseUser) -> Ranking | None:
    """The racer's ranking in ``event`` from scratch: their best qualified submission that is not
    disqualified, or no ranking at all."""
    with transaction.atomic():
        _lock(racer)
        best = (
            Submission.objects.filter(event=event, racer=racer, qualified=True, disqualified=False)
            .order_by("score_ms", "created_at", "pk")
            .first()
        )
        ranking = Ranking.objects.filter(event=event, racer=racer).first()
        if best is None:
            if ranking is not None:
                ranking.delete()
            return None
        return _rank(best, ranking)


def event_rankings_recompute(*, event: Event) -> int:
    """Every ranking of ``event`` from its submissions (the admin's "Recompute rankings"); how
    many racers are ranked afterwards."""
    racers = set(event.submissions.values_list("racer", flat=True)) | set(
        event.rankings.values_list("racer", flat=True)
    )
    for racer in get_user_model().objects.filter(pk__in=racers):
        ranking_recompute(event=event, racer=racer)
    broadcasts.announce_leaderboard(event)
    return event.rankings.count()


def submission_disqualify(*, submission: Submission, reason: str) -> Submission:
    """Take the submission out of the ranking (league staff) for ``reason``; the racer's next
    best takes its place, and the racer is told why (again when the reason changes)."""
    reason = reason.strip()[:255]
    news = not submission.disqualified or submission.disqualification_reason != reason
    _update(submission, disqualified=True, disqualification_reason=reason)
    ranking_recompute(event=submission.event, racer=submission.racer)
    broadcasts.announce_leaderboard(submission.event)
    if news:
        notifications.submission_disqualified(submission=submission)
    return submission


def submission_reinstate(*, submission: Submission) -> Submission:
    """Count a disqualified submission again (league staff): its reason goes, its place on the
    leaderboard comes back where it is the racer's best, and the leaderboard says so."""
    _update(submission, disqualified=False, disqualification_reason="")
    ranking_recompute(event=submission.event, racer=submission.racer)
    broadcasts.announce_leaderboard(submission.event)
    return submission


# Events


def event_close(*, event: Event) -> Event:
    """Close the event now (races already submitted still finish and count)."""
    now = timezone.now()
    if event.closes_at > now:
        event.closes_at = now
        event.opens_at = min(event.opens_at, now)
        event.save(update_fields=["opens_at", "closes_at"])
    broadcasts.announce_leaderboard(event)
    return event


class RaceMade(enum.Enum):
    """How ``community_race_create`` came by the race it gives back."""

    NEW = "new"
    BY_THIS_FORM = "by this form"  # the same form sent again: a double click, or Back
    ALIKE = "alike"  # the same settings from a fresh form, a moment ago: Back, refetched


def community_race_create(
    *, organiser: AbstractBaseUser, fields: dict, form_token: str = ""
) -> tuple[Event, RaceMade]:
    """A private event that ``organiser`` runs (a community race), entered through its
    invitation link; ``ValidationError`` lists what is wrong with ``fields``. The form's
    one-time ``form_token`` makes it idempotent: the same form sent again (a double click)
    gives back the race it created, and refuses in words when its fields were changed. Back
    and submit again may send the same settings from a fresh form (Chromium fetches the form
    anew and keeps what was typed): the race made with them within ``RESUBMIT_WINDOW`` is given
    back too. The race, and how it was come by."""
    event = Event(**fields, organiser=organiser, public=False, season=None, division=Division.OPEN)
    event.slug = _free_slug(fields.get("name") or "race")
    event.form_token = form_token
    event.ensure_invite()
    # The one-race-per-form constraint is the database's to enforce, below: a twin request
    # that saved first is found there, not reported as an error in the form.
    event.full_clean(validate_constraints=False)
    if form_token and (made := _race_from_form(organiser, form_token)):
        return _made_by_this_form(made, event, fields), RaceMade.BY_THIS_FORM
    if made := _same_race_just_made(organiser, event, fields):
        return made, RaceMade.ALIKE
    try:
        with transaction.atomic():
            event.save()
            event.participants.add(organiser)
    except IntegrityError:  # the same form, sent twice at once: the other request made it
        if made := _race_from_form(organiser, form_token):
            return _made_by_this_form(made, event, fields), RaceMade.BY_THIS_FORM
        raise
    return event, RaceMade.NEW


def _race_from_form(organiser: AbstractBaseUser, form_token: str) -> Event | None:
    return Event.objects.filter(organiser=organiser, form_token=form_token).first()


def _made_by_this_form(made: Event, event: Event, fields: dict) -> Event:
    """The race this form made, when ``event`` asks for it again; a form sent again with other
    settings (Back, a change, submit) is refused, so that no change is silently lost."""
    if not _alike(made, event, fields, leeway=timedelta(0)):
        raise ValidationError(
            f"This form already created {made.name}; open the form again to organise another race."
        )
    return made


def _same_race_just_made(organiser: AbstractBaseUser, event: Event, fields: dict) -> Event | None:
    """The organiser's race with ``event``'s settings made within ``RESUBMIT_WINDOW``, its
    times within that much of ``event``'s (a fresh form starts them at its own now)."""
    since = timezone.now() - RESUBMIT_WINDOW
    for made in Event.objects.filter(organiser=organiser, public=False, created_at__gte=since):
        if _alike(made, event, fields, leeway=RESUBMIT_WINDOW):
            return made
    return None


def _alike(made: Event, event: Event, fields: dict, *, leeway: timedelta) -> bool:
    """Whether ``made`` has every setting the form gave (``fields``: the community race
    form's fields, so a field added to the form is compared too), its times within
    ``leeway``."""
    for name in fields:
        attname = Event._meta.get_field(name).attname
        mine, theirs = getattr(made, attname), getattr(event, attname)
        if isinstance(mine, datetime) and isinstance(theirs, datetime):
            if abs(mine - theirs) > leeway:
                return False
        elif mine != theirs:
            return False
    return True


class RaceNotDeleted(Refused):
    """The organiser cannot delete this community race; the message says why."""


def community_race_delete(*, event: Event) -> None:
    """Delete a community race nobody has raced in yet (``RaceNotDeleted`` once it has
    submissions: their racers' runs and places stay; the organiser may close it instead)."""
    with transaction.atomic():
        if _lock_event(event) is None:
            return  # deleted already: a second click
        reason = selectors.race_deletion_refusal(event=event)
        if reason:
            raise RaceNotDeleted(reason)
        event.delete()


def _free_slug(name: str) -> str:
    base = slugify(name)[:80] or "race"
    while True:
        slug = f"{base}-{get_random_string(6, 'abcdefghijkmnpqrstuvwxyz23456789')}"
        if not Event.objects.filter(slug=slug).exists():
            return slug


def event_join(*, event: Event, racer: AbstractBaseUser) -> None:
    """The racer accepts a community race's invitation (``SubmissionRefused`` once it closed,
    or when the organiser took them out)."""
    reason = selectors.invitation_refusal(event=event, racer=racer)
    if reason:
        raise SubmissionRefused(reason)
    event.participants.add(racer)


def participant_remove(*, event: Event, racer: AbstractBaseUser) -> None:
    """The organiser takes a racer out of their community race, with the racer's ranking; the
    invitation no longer lets them back in (the organiser may, with ``participant_readmit``)."""
    if racer.pk == event.organiser_id:
        raise SubmissionRefused("The organiser stays in their own race.")
    with transaction.atomic():
        event.participants.remove(racer)
        event.removed.add(racer)
        Ranking.objects.filter(event=event, racer=racer).delete()
    broadcasts.announce_leaderboard(event)


def participant_readmit(*, event: Event, racer: AbstractBaseUser) -> None:
    """The organiser lets a racer they took out back into their community race (their earlier
    runs rank again)."""
    with transaction.atomic():
        event.removed.remove(racer)
        event.participants.add(racer)
    ranking_recompute(event=event, racer=racer)
    broadcasts.announce_leaderboard(event)


def invitation_renew(*, event: Event) -> str:
    """A new invitation link for the community race; the old one stops working (racers who
    joined stay in)."""
    event.invite_token = ""
    token = event.ensure_invite()
    event.save(update_fields=["invite_token"])
    return token


def event_winner_show(*, event: Event, shown: bool = True) -> dict | None:
    """The organiser shows the winner on the broadcast (or hides it again): kept on the event,
    so that a broadcast opened or reloaded later shows it too. The winner shown, if any: with
    nobody ranked there is none, and nothing is kept that would cover the race once someone is."""
    if shown and not selectors.leaders(event=event, count=1):
        return None
    event.winner_shown_at = timezone.now() if shown else None
    Event.objects.filter(pk=event.pk).update(winner_shown_at=event.winner_shown_at)
    winner = selectors.winner_shown(event=event)
    broadcasts.announce_winner(event, winner)
    return winner


# Divisions


def divisions_promote(*, today: date | None = None) -> list[Racer]:
    """The monthly promotion: the racers in the top 10% (at least one) of each of last month's
    public Open time trials move up to Pro, unless staff set their division. Running it again
    changes nothing; the racers promoted are returned."""
    today = today or timezone.localdate()
    this_month = _start_of(today.replace(day=1))
    last_month = _start_of((today.replace(day=1) - timedelta(days=1)).replace(day=1))
    events = Event.objects.filter(
        public=True,
        division=Division.OPEN,
        race_type=RaceType.TIME_TRIAL,
        closes_at__gte=last_month,
        closes_at__lt=this_month,
    )
    winners: set[int] = set()
    for event in events:
        ranked = event.rankings.count()
        top = event.rankings.order_by(*RANKING_ORDER)[: math.ceil(ranked * PROMOTED_SHARE)]
        winners.update(top.values_list("racer_id", flat=True))
    promoted = []
    for user_id in sorted(winners):
        racer, _ = Racer.objects.get_or_create(user_id=user_id)
        if racer.division == Division.OPEN and not racer.division_set_by_staff:
            racer.division, racer.promoted_at = Division.PRO, timezone.now()
            racer.save(update_fields=["division", "promoted_at"])
            promoted.append(racer)
    logger.info("Promoted %d racers to Pro from %d events", len(promoted), len(events))
    return promoted


# The demo season


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
            "boxes": {"count": 3, "randomize": False},
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


def submissions_waiting(sender, *, waiting: dict[str, set], **kwargs) -> set[int]:
    """On ``training.signals.evaluations_waiting``: the evaluations of the race entries whose race
    task is waiting in the broker (``waiting``: the first arguments of its messages, by task)."""
    ids = sorted(pk for pk in waiting.get("racing.race", ()) if isinstance(pk, int))
    found: set[int] = set()
    for start in range(0, len(ids), 500):  # within SQLite's limit on a query's parameters
        rows = Submission.objects.filter(pk__in=ids[start : start + 500], evaluation__isnull=False)
        found.update(rows.values_list("evaluation_id", flat=True))
    return found


def submission_resend(sender, *, evaluation: EvaluationJob, **kwargs) -> bool:
    """On ``training.signals.evaluation_lapsed``: a race entry's evaluation lost its simulation
    worker, so the race is sent again (it drives the evaluation from the start, then scores
    it); False when the evaluation is no race's."""
    submission = Submission.objects.filter(evaluation=evaluation).only("pk").first()
    if submission is None:
        return False
    transaction.on_commit(lambda: queueing.enqueue(RACE, submission.pk))
    return True
