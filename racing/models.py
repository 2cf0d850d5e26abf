"""The league: seasons hold events; racers submit models to events; a submission's laps give its
score, and a racer's best qualifying score per event is their ranking. Live sessions queue an
event's turns, and physical runs time real cars' laps into the same submissions.

Long because the league's rows are one schema that its services, pages and admin read together:
an event's rules, its submissions, their laps and rankings, and the live and physical races
that make submissions, side by side as a reader of a race's data expects them.
"""

from __future__ import annotations

import secrets
from datetime import date, datetime, time, timedelta

from django.conf import settings
from django.core.exceptions import ValidationError
from django.core.validators import MaxValueValidator, MinValueValidator
from django.db import models
from django.urls import reverse
from django.utils import timezone

from racing import scoring
from simulator.config import MAX_CARS
from training import configuration
from training.configuration import PENALTY_MAX
from training.models import EvaluationJob, RaceConditions, RaceType, RLModel, Track

# The shortest lap a real 1/18 car can drive, the default of an event's ``min_lap_s`` [s]: the
# shortest DeepRacer track, A to Z Speedway (16.6 m, simulator/tracks/data/deepracer/catalog.json),
# at the car's 4 m/s top speed (simulator.config.SPEED_RANGE) takes 4.15 s. DREM has no
# per-event minimum; its timing gate ignores a second trigger within 2 s (debounceMs:
# guidance-for-aws-deepracer-event-management@18030a1 leaderboard-timer/timer.js:12 and :89-93).
MIN_LAP_S = 4.0
MIN_LAP_S_RANGE = (0.5, 600.0)  # [s]
# A racer's time on the track, at most [min]: DREM offers 1 to 10 minutes, 2 by default
# (website/src/admin/events/support-functions/raceConfig.js RaceTimeConfig, eventDomain.js:11).
RACE_TIME_MAX_MIN = 10


class Division(models.TextChoices):
    OPEN = "OPEN", "Open"
    PRO = "PRO", "Pro"


class RankingMethod(models.TextChoices):
    FIRST_CONSECUTIVE = scoring.FIRST_CONSECUTIVE, "Average of the first N consecutive laps"
    BEST_CONSECUTIVE = scoring.BEST_CONSECUTIVE, "Best average of N consecutive laps"
    BEST_LAP = scoring.BEST_LAP, "Best lap"
    TOTAL_TIME = scoring.TOTAL_TIME, "Total time"


class Racer(models.Model):
    """A user's place in the league: their division. Everyone starts in Open; the monthly
    promotion moves the top 10% of the Open time trials to Pro, unless staff set the division."""

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="league"
    )
    division = models.CharField(max_length=8, choices=Division.choices, default=Division.OPEN)
    division_set_by_staff = models.BooleanField(
        default=False, help_text="Staff chose the division: the monthly promotion leaves it alone."
    )
    promoted_at = models.DateTimeField(null=True, blank=True)

    class Meta:
        verbose_name = "racer's division"
        verbose_name_plural = "racers' divisions"

    def __str__(self) -> str:
        return f"{self.user} ({self.get_division_display()})"

    @classmethod
    def of(cls, user) -> Racer:
        return cls.objects.get_or_create(user=user)[0]


class Season(models.Model):
    name = models.CharField(max_length=100, unique=True)
    year = models.PositiveSmallIntegerField()
    starts_on = models.DateField()
    ends_on = models.DateField()

    class Meta:
        ordering = ["-starts_on"]

    def __str__(self) -> str:
        return self.name


class Event(RaceConditions):
    class State(models.TextChoices):
        UPCOMING = "upcoming", "Upcoming"
        OPEN = "open", "Open"
        CLOSED = "closed", "Closed"

    season = models.ForeignKey(
        Season,
        null=True,
        blank=True,
        on_delete=models.CASCADE,
        related_name="events",
        help_text="Empty for a community race.",
    )
    name = models.CharField(max_length=100)
    slug = models.SlugField(max_length=100, unique=True)
    track = models.ForeignKey(Track, on_delete=models.PROTECT, related_name="events")
    division = models.CharField(max_length=8, choices=Division.choices, default=Division.OPEN)
    any_division = models.BooleanField(
        "open to both divisions",
        default=False,
        help_text="Racers of either division may enter, as the organiser says, without moving "
        "anyone between divisions; its points count in its own division's standings.",
    )
    opens_at = models.DateTimeField()
    closes_at = models.DateTimeField()
    ranking_method = models.CharField(
        max_length=24, choices=RankingMethod.choices, default=RankingMethod.FIRST_CONSECUTIVE
    )
    laps_required = models.PositiveSmallIntegerField(
        "consecutive laps to qualify (N)",
        default=3,
        validators=[MinValueValidator(1), MaxValueValidator(20)],
    )
    laps_to_drive = models.PositiveSmallIntegerField(
        "laps to drive",
        default=3,
        validators=[MinValueValidator(1), MaxValueValidator(20)],
        help_text="The car drives this many laps without stopping; at least N.",
    )
    off_track_penalty_s = models.FloatField(
        "off-track penalty [s]",
        default=2.0,
        validators=[MinValueValidator(0), MaxValueValidator(PENALTY_MAX)],
    )
    crash_penalty_s = models.FloatField(
        "crash penalty [s]",
        default=5.0,
        validators=[MinValueValidator(0), MaxValueValidator(PENALTY_MAX)],
    )
    max_off_tracks_per_lap = models.PositiveSmallIntegerField(
        "off-tracks allowed per lap",
        null=True,
        blank=True,
        help_text="A lap with more off-tracks does not count. Empty: any number.",
    )
    submissions_per_racer = models.PositiveSmallIntegerField(
        default=10, validators=[MinValueValidator(1), MaxValueValidator(1000)]
    )
    public = models.BooleanField(
        default=True, help_text="A private event is a community race: entered by invitation."
    )
    organiser = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        blank=True,
        on_delete=models.CASCADE,
        related_name="organised_events",
        help_text="The racer who runs a community race.",
    )
    invite_token = models.CharField(max_length=43, blank=True, db_index=True)
    participants = models.ManyToManyField(
        settings.AUTH_USER_MODEL,
        blank=True,
        related_name="joined_events",
        help_text="Who may enter a private event (through its invitation).",
    )
    removed = models.ManyToManyField(
        settings.AUTH_USER_MODEL,
        blank=True,
        related_name="removed_from_events",
        verbose_name="racers taken out",
        help_text="Racers the organiser took out: the invitation no longer lets them back in.",
    )
    form_token = models.CharField(
        max_length=43,
        blank=True,
        editable=False,
        help_text="The one-time token of the form that created this community race: the same "
        "form sent twice (Back and submit again, a double click) gives back this race.",
    )
    cars = models.PositiveSmallIntegerField(
        "cars a race",
        default=1,
        validators=[MinValueValidator(1), MaxValueValidator(MAX_CARS)],
        help_text="Model against model (DeepRacer for Cloud's HEAD_TO_MODEL): 2 to 4 racers' "
        "models on the track at once, each entry against the leaders' models (or, raced live, "
        "the next racers in the queue). 1: each model alone.",
    )
    physical = models.BooleanField(
        "raced by real cars",
        default=False,
        help_text="Real cars at a venue: a timekeeper records each lap (the event's timekeeper "
        "page, or a timing device), and the laps are scored by the same rules.",
    )
    timing_token_hash = models.CharField(
        max_length=64,
        blank=True,
        editable=False,
        help_text="SHA-256 of the token a timing device sends (racing.timing); the token itself "
        "is shown once, when it is made.",
    )
    min_lap_s = models.FloatField(
        "shortest lap [s]",
        default=MIN_LAP_S,
        validators=[MinValueValidator(MIN_LAP_S_RANGE[0]), MaxValueValidator(MIN_LAP_S_RANGE[1])],
        help_text="Real cars: a crossing sooner than this after the last one is refused (a "
        "double press, a gate's bounce), and the timekeeper is told why.",
    )
    race_time_min = models.PositiveSmallIntegerField(
        "race time per racer [min]",
        null=True,
        blank=True,
        validators=[MinValueValidator(1), MaxValueValidator(RACE_TIME_MAX_MIN)],
        help_text="Real cars: each racer's time on the track, counted down from their first "
        "crossing on the timekeeper's page and the broadcast; a crossing after it is not "
        "counted (the DeepRacer Event Manager's race time: 1-10 min, 2 by default). Empty: "
        "no limit.",
    )
    winner_shown_at = models.DateTimeField(
        null=True,
        blank=True,
        editable=False,
        help_text="When the organiser showed the winner on the broadcast (empty: not shown); a "
        "broadcast opened later shows it too.",
    )
    created_at = models.DateTimeField(auto_now_add=True, null=True, editable=False)

    class Meta:
        ordering = ["opens_at", "name"]
        constraints = [
            models.UniqueConstraint(
                fields=["organiser", "form_token"],
                condition=~models.Q(form_token=""),
                name="one_race_per_form",
            )
        ]

    def __str__(self) -> str:
        return self.name

    def get_absolute_url(self) -> str:
        return reverse("racing:leaderboard", args=[self.slug])

    def clean(self) -> None:
        errors = {}
        if self.opens_at and self.closes_at and self.closes_at <= self.opens_at:
            errors["closes_at"] = "An event closes after it opens."
        if self.laps_required and self.laps_to_drive and self.laps_to_drive < self.laps_required:
            errors["laps_to_drive"] = (
                f"Drive at least the {self.laps_required} consecutive laps that qualify."
            )
        if self.public and self.division == Division.OPEN and self.race_type != RaceType.TIME_TRIAL:
            errors["race_type"] = (
                "Open events are time trials; object avoidance and head-to-bot are Pro events."
            )
        if self.public and self.division == Division.OPEN and self.cars > 1:
            errors["cars"] = "Open events are time trials, one car at a time; model against "
            errors["cars"] += "model is a Pro event."
        if self.physical and self.cars > 1:
            errors["cars"] = "Real cars are timed one at a time: an event raced by real cars has "
            errors["cars"] += "one car a race."
        # An inline event of a season being added holds the unsaved season, not its id yet.
        cached = self._meta.get_field("season").is_cached(self)
        season = self.season if self.season_id or cached else None
        if self.public and season is None:
            errors["season"] = "A league event belongs to a season."
        if season is not None and self.opens_at and self.closes_at:
            errors.update(self._outside(season))
        if self.track_id and self.direction and not getattr(self.track, self.direction):
            errors["direction"] = (
                f"{self.track} cannot be driven {self.get_direction_display().lower()}."
            )
        try:
            race = configuration.check_race(
                {"race_type": self.race_type, "boxes": self.boxes, "bots": self.bots}
            )
        except configuration.Invalid as invalid:
            errors["race_type"] = list(invalid.errors.values())
        else:
            self.boxes, self.bots = race["boxes"], race["bots"]
        if errors:
            raise ValidationError(errors)

    def _outside(self, season: Season) -> dict[str, str]:
        """Errors for the times that fall outside the season's days (in this request's zone)."""
        starts = timezone.make_aware(datetime.combine(season.starts_on, time.min))
        ends = timezone.make_aware(datetime.combine(season.ends_on + timedelta(days=1), time.min))
        days = f"{season.name} runs from {_day(season.starts_on)} to {_day(season.ends_on)}"
        errors = {}
        if not starts <= self.opens_at < ends:
            errors["opens_at"] = f"{days}: open the event within those days."
        if not starts < self.closes_at <= ends:
            errors["closes_at"] = f"{days}: close the event by the end of its last day."
        return errors

    def ensure_invite(self) -> str:
        if not self.invite_token:
            self.invite_token = secrets.token_urlsafe(32)
        return self.invite_token

    @property
    def state(self) -> Event.State:
        now = timezone.now()
        if now < self.opens_at:
            return self.State.UPCOMING
        if now < self.closes_at:
            return self.State.OPEN
        return self.State.CLOSED

    @property
    def is_open(self) -> bool:
        return self.state == self.State.OPEN

    @property
    def ranking_rule(self) -> str:
        """How runs are ranked, in words, with N filled in: "average of the first 3 consecutive
        laps"."""
        rule = self.get_ranking_method_display().replace(" N ", f" {self.laps_required} ")
        return rule[0].lower() + rule[1:]

    def lap_counts(self, *, off_tracks: int) -> bool:
        """Whether a complete lap with ``off_tracks`` counts: within the event's off-track limit
        per lap (none: any number)."""
        limit = self.max_off_tracks_per_lap
        return limit is None or off_tracks <= limit

    @property
    def format_display(self) -> str:
        """What kind of race it is, in a few words for lists: "Time trial, real cars",
        "Head-to-bot, 2 cars a race" (model against model), or the race type alone."""
        kind = self.get_race_type_display()
        if self.physical:
            return f"{kind}, real cars"
        return f"{kind}, {self.cars} cars a race" if self.cars > 1 else kind

    @property
    def division_display(self) -> str:
        """The division(s) that may enter: "Open", "Pro", or "Open and Pro"."""
        return "Open and Pro" if self.any_division else self.get_division_display()

    @property
    def laps_to_qualify(self) -> int:
        """Counted laps in a row a run needs to rank. Real cars raced for the best lap rank any
        counted lap, as DREM's fastest-lap format does (its BEST_LAP_TIME ranks the fastest valid
        lap of any race: guidance-for-aws-deepracer-event-management@18030a1
        lib/lambdas/pdf_api/race_summary.py:48 and :68-70); otherwise N."""
        if self.physical and self.ranking_method == RankingMethod.BEST_LAP:
            return 1
        return self.laps_required

    @property
    def qualifying_rule(self) -> str:
        """What a run needs to rank, in words: "one counted lap ranks" or "a run ranks once it
        has 3 counted laps in a row"."""
        if self.laps_to_qualify == 1:
            return "any counted lap ranks: one is enough to qualify"
        return f"a run ranks once it has {self.laps_to_qualify} counted laps in a row"


def _day(day: date) -> str:
    return f"{day.day} {day:%B %Y}"


class Submission(models.Model):
    """A racer's model entered in an event: an evaluation under the event's rules, then its laps
    and score. It keeps the model's name, laps and video when the model is deleted."""

    Status = EvaluationJob.Status
    ACTIVE = EvaluationJob.ACTIVE

    event = models.ForeignKey(Event, on_delete=models.CASCADE, related_name="submissions")
    racer = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="submissions"
    )
    model = models.ForeignKey(
        RLModel, null=True, blank=True, on_delete=models.SET_NULL, related_name="submissions"
    )
    model_name = models.CharField(max_length=64)
    evaluation = models.OneToOneField(
        EvaluationJob, null=True, blank=True, on_delete=models.SET_NULL, related_name="submission"
    )
    # Kept here as well as on its evaluation, which goes with the model: what drove the race.
    checkpoint = models.CharField(
        max_length=8,
        choices=EvaluationJob.Checkpoint.choices,
        default=EvaluationJob.Checkpoint.BEST,
        help_text="The model's best or last checkpoint.",
    )
    checkpoint_iteration = models.PositiveIntegerField(
        null=True, blank=True, help_text="The training iteration whose weights raced."
    )
    seed = models.PositiveIntegerField(
        null=True, blank=True, help_text="Its evaluation's seed: the same seed races it again."
    )
    status = models.CharField(max_length=16, choices=Status.choices, default=Status.QUEUED)
    failure_reason = models.TextField(blank=True)
    created_at = models.DateTimeField("submitted", auto_now_add=True, db_index=True)
    finished_at = models.DateTimeField(null=True, blank=True)
    score_ms = models.PositiveIntegerField("score [ms]", null=True, blank=True)
    qualified = models.BooleanField(default=False)
    laps_completed = models.PositiveSmallIntegerField(default=0)
    off_tracks = models.PositiveIntegerField(default=0)
    video = models.CharField(max_length=255, blank=True, help_text="Storage name of the video.")
    disqualified = models.BooleanField(default=False)
    disqualification_reason = models.CharField(max_length=255, blank=True)
    physical = models.BooleanField(
        default=False, help_text="A real car's laps, timed at the track (racing.timing)."
    )

    class Meta:
        ordering = ["-created_at", "-pk"]
        indexes = [
            models.Index(fields=["event", "racer", "created_at"]),
            models.Index(fields=["racer", "created_at"]),
        ]

    def __str__(self) -> str:
        return f"{self.model_name} in {self.event} (#{self.pk})"

    def get_absolute_url(self) -> str:
        return reverse("racing:submission-detail", args=[self.pk])

    @property
    def is_active(self) -> bool:
        return self.status in self.ACTIVE

    @property
    def disqualification_text(self) -> str:
        """The word Disqualified, with the staff's reason when they gave one, never twice."""
        reason = self.disqualification_reason.strip()
        if not reason:
            return "Disqualified"
        if reason.lower().startswith("disqualified"):
            return reason
        return f"Disqualified: {reason}"

    @property
    def ranked_score(self) -> int | None:
        """The score that may rank: a qualified, not disqualified submission's."""
        return self.score_ms if self.qualified and not self.disqualified else None


class LiveSession(models.Model):
    """An event raced live (racing.live_races): racers queue their models, the facilitator orders
    the queue and launches each turn, and everyone on the race page watches it drive."""

    event = models.OneToOneField(Event, on_delete=models.CASCADE, related_name="live_session")
    facilitator = models.ForeignKey(
        settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL, related_name="+"
    )
    autolaunch = models.BooleanField(
        default=False, help_text="Launch the next turn as soon as one ends."
    )
    min_speed = models.FloatField(
        "slowest speed multiplier",
        default=0.5,
        validators=[MinValueValidator(0.1), MaxValueValidator(2.0)],
    )
    max_speed = models.FloatField(
        "fastest speed multiplier",
        default=1.5,
        validators=[MinValueValidator(0.1), MaxValueValidator(2.0)],
    )
    created_at = models.DateTimeField(auto_now_add=True)

    def __str__(self) -> str:
        return f"{self.event} live"


class LiveEntry(models.Model):
    """A racer's place in a live session's queue, and the turn it drove."""

    class Status(models.TextChoices):
        WAITING = "waiting", "Waiting"
        DRIVING = "driving", "Driving"
        DONE = "done", "Done"
        REMOVED = "removed", "Removed"

    session = models.ForeignKey(LiveSession, on_delete=models.CASCADE, related_name="entries")
    racer = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="live_entries"
    )
    model = models.ForeignKey(RLModel, null=True, on_delete=models.SET_NULL, related_name="+")
    model_name = models.CharField(max_length=64)
    speed = models.FloatField("speed multiplier", default=1.0)
    position = models.PositiveIntegerField(help_text="Its place in the queue: lower goes first.")
    status = models.CharField(max_length=8, choices=Status.choices, default=Status.WAITING)
    submission = models.OneToOneField(
        Submission, null=True, blank=True, on_delete=models.SET_NULL, related_name="live_entry"
    )
    joined_at = models.DateTimeField(auto_now_add=True)

    class Meta:
        ordering = ["session", "position", "pk"]
        verbose_name_plural = "live entries"

    def __str__(self) -> str:
        return f"{self.model_name} in {self.session}"


class PhysicalRun(models.Model):
    """A real car on the track: its physical submission's timing while the timekeeper records it
    (racing.timing). Lap times are differences of one clock's readings, the timekeeper page's or
    the timing device's, so neither clock need agree with the server's."""

    submission = models.OneToOneField(
        Submission, on_delete=models.CASCADE, related_name="physical_run"
    )
    car = models.CharField(max_length=64, help_text="Which car: its number or name.")
    timekeeper = models.ForeignKey(
        settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL, related_name="+"
    )
    line_crossed_ms = models.BigIntegerField(
        null=True,
        blank=True,
        help_text="The clock's reading when the car last crossed the line: "
        "the lap on track started then. Empty until the first crossing.",
    )
    started_at = models.DateTimeField(
        null=True,
        blank=True,
        help_text="When the server heard the first crossing: the racer's race time runs from "
        "then (Event.race_time_min).",
    )
    line_crossed_at = models.DateTimeField(
        null=True,
        blank=True,
        help_text="When the server heard that crossing (the broadcast's timer).",
    )
    off_tracks = models.PositiveIntegerField(default=0, help_text="Of the lap on track.")
    resets = models.PositiveIntegerField(default=0, help_text="Of the lap on track.")

    def __str__(self) -> str:
        return f"{self.car} for {self.submission}"

    @property
    def race_ends_at(self) -> datetime | None:
        """When the racer's race time runs out (the event's, from the first crossing); None
        before that crossing or with no race time."""
        minutes = self.submission.event.race_time_min
        if minutes is None or self.started_at is None:
            return None
        return self.started_at + timedelta(minutes=minutes)


class Lap(models.Model):
    """One lap of a submission, as the race's evaluation drove it (penalties in the time)."""

    submission = models.ForeignKey(Submission, on_delete=models.CASCADE, related_name="laps")
    number = models.PositiveSmallIntegerField()
    time_ms = models.PositiveIntegerField("time [ms]")
    status = models.CharField(max_length=20, help_text="lap_complete, or time_up when cut short.")
    counted = models.BooleanField(help_text="Complete, within the event's off-track limit.")
    off_tracks = models.PositiveIntegerField(default=0)
    crashes = models.PositiveIntegerField(default=0)
    resets = models.PositiveIntegerField(default=0)
    penalty_ms = models.PositiveIntegerField("penalty [ms]", default=0)
    struck_at = models.DateTimeField(
        null=True, blank=True, help_text="When the timekeeper struck it out: it does not count."
    )
    struck_by = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        blank=True,
        on_delete=models.SET_NULL,
        related_name="+",
        help_text="The timekeeper who struck it out.",
    )

    class Meta:
        ordering = ["submission", "number"]
        constraints = [
            models.UniqueConstraint(fields=["submission", "number"], name="one_row_per_lap")
        ]

    def __str__(self) -> str:
        return f"lap {self.number}"

    def scoring_lap(self) -> scoring.Lap:
        return scoring.Lap(self.time_ms, self.counted)


class LapEdit(models.Model):
    """A timekeeper's change to a real car's laps after they were timed (racing.lap_edits): what,
    to which lap, who and when. DREM's race admin edits a race's laps the same way (its
    editRace page: guidance-for-aws-deepracer-event-management@18030a1
    website/src/admin/race-admin/pages/editRace.tsx:82-124)."""

    class Action(models.TextChoices):
        STRIKE = "strike", "Struck out"
        RESTORE = "restore", "Restored"
        SPLIT = "split", "Split at a missed crossing"
        ADD = "add", "Added"

    submission = models.ForeignKey(Submission, on_delete=models.CASCADE, related_name="lap_edits")
    lap_number = models.PositiveSmallIntegerField()
    action = models.CharField(max_length=8, choices=Action.choices)
    detail = models.CharField(max_length=200, blank=True)
    by = models.ForeignKey(
        settings.AUTH_USER_MODEL, null=True, on_delete=models.SET_NULL, related_name="+"
    )
    at = models.DateTimeField(default=timezone.now)

    class Meta:
        ordering = ["submission", "at", "pk"]

    def __str__(self) -> str:
        return f"{self.get_action_display()} lap {self.lap_number}"


# Places on a leaderboard: the lower score, then the earlier submission, then the older row.
RANKING_ORDER = ("score_ms", "submitted_at", "id")


class Ranking(models.Model):
    """A racer's best qualifying score in one event (lower is better)."""

    event = models.ForeignKey(Event, on_delete=models.CASCADE, related_name="rankings")
    racer = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="rankings"
    )
    submission = models.ForeignKey(Submission, on_delete=models.CASCADE, related_name="+")
    model_name = models.CharField(max_length=64)
    score_ms = models.PositiveIntegerField("score [ms]")
    submitted_at = models.DateTimeField()
    laps_completed = models.PositiveSmallIntegerField(default=0)
    off_tracks = models.PositiveIntegerField(default=0)

    class Meta:
        ordering = ["event", *RANKING_ORDER]
        constraints = [
            models.UniqueConstraint(fields=["event", "racer"], name="one_ranking_per_racer")
        ]
        indexes = [models.Index(fields=["event", *RANKING_ORDER])]

    def __str__(self) -> str:
        return f"{self.racer} in {self.event}"
