"""The league: seasons hold events; a racer's best qualifying score per event is their ranking."""

from django.conf import settings
from django.core.validators import MaxValueValidator, MinValueValidator
from django.db import models
from django.urls import reverse
from django.utils import timezone

from training.models import Direction, RaceType, Track


class Division(models.TextChoices):
    OPEN = "OPEN", "Open"
    PRO = "PRO", "Pro"


class RankingMethod(models.TextChoices):
    FIRST_CONSECUTIVE = "FIRST_CONSECUTIVE", "Average of the first N consecutive laps"
    BEST_CONSECUTIVE = "BEST_CONSECUTIVE", "Best average of N consecutive laps"
    BEST_LAP = "BEST_LAP", "Best lap"
    TOTAL_TIME = "TOTAL_TIME", "Total time"


class Season(models.Model):
    name = models.CharField(max_length=100, unique=True)
    year = models.PositiveSmallIntegerField()
    starts_on = models.DateField()
    ends_on = models.DateField()

    class Meta:
        ordering = ["-starts_on"]

    def __str__(self) -> str:
        return self.name


class Event(models.Model):
    class State(models.TextChoices):
        UPCOMING = "upcoming", "Upcoming"
        OPEN = "open", "Open"
        CLOSED = "closed", "Closed"

    season = models.ForeignKey(Season, on_delete=models.CASCADE, related_name="events")
    name = models.CharField(max_length=100)
    slug = models.SlugField(max_length=100, unique=True)
    track = models.ForeignKey(Track, on_delete=models.PROTECT, related_name="events")
    direction = models.CharField(
        max_length=16, choices=Direction.choices, default=Direction.COUNTERCLOCKWISE
    )
    race_type = models.CharField(max_length=16, choices=RaceType.choices)
    division = models.CharField(max_length=8, choices=Division.choices, default=Division.OPEN)
    opens_at = models.DateTimeField()
    closes_at = models.DateTimeField()
    ranking_method = models.CharField(
        max_length=24, choices=RankingMethod.choices, default=RankingMethod.FIRST_CONSECUTIVE
    )
    laps_required = models.PositiveSmallIntegerField(
        default=3, validators=[MinValueValidator(1), MaxValueValidator(20)]
    )
    off_track_penalty_s = models.FloatField(
        "off-track penalty [s]", default=2.0, validators=[MinValueValidator(0)]
    )
    crash_penalty_s = models.FloatField(
        "crash penalty [s]", default=5.0, validators=[MinValueValidator(0)]
    )

    class Meta:
        ordering = ["opens_at", "name"]

    def __str__(self) -> str:
        return self.name

    def get_absolute_url(self) -> str:
        return reverse("racing:leaderboard", args=[self.slug])

    @property
    def state(self) -> "Event.State":
        now = timezone.now()
        if now < self.opens_at:
            return self.State.UPCOMING
        if now < self.closes_at:
            return self.State.OPEN
        return self.State.CLOSED


class Ranking(models.Model):
    """A racer's best qualifying score in one event (lower is better)."""

    event = models.ForeignKey(Event, on_delete=models.CASCADE, related_name="rankings")
    racer = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="rankings"
    )
    model_name = models.CharField(max_length=64)
    score_ms = models.PositiveIntegerField("score [ms]")
    submitted_at = models.DateTimeField()

    class Meta:
        ordering = ["event", "score_ms", "submitted_at"]
        constraints = [
            models.UniqueConstraint(fields=["event", "racer"], name="one_ranking_per_racer")
        ]
        indexes = [models.Index(fields=["event", "score_ms", "submitted_at"])]

    def __str__(self) -> str:
        return f"{self.racer} in {self.event}"
