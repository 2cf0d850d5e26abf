"""A racer's models, and the tracks they train on."""

from django.conf import settings
from django.core.validators import RegexValidator
from django.db import models


class Direction(models.TextChoices):
    COUNTERCLOCKWISE = "counterclockwise", "Counter-clockwise"
    CLOCKWISE = "clockwise", "Clockwise"


class Track(models.Model):
    """A built-in track from ``simulator.tracks``, mirrored here so pages and forms can list it.

    ``manage.py loadtracks`` keeps these rows in step with the simulator's catalogue.
    """

    class Difficulty(models.TextChoices):
        BEGINNER = "beginner"
        INTERMEDIATE = "intermediate"
        ADVANCED = "advanced"
        EXPERT = "expert"

    name = models.SlugField(max_length=64, unique=True, help_text="The simulator's track name.")
    display_name = models.CharField(max_length=100)
    description = models.CharField(max_length=255, blank=True)
    difficulty = models.CharField(max_length=16, choices=Difficulty.choices)
    length_m = models.FloatField("length [m]")
    width_m = models.FloatField("width [m]")
    counterclockwise = models.BooleanField(default=True)
    clockwise = models.BooleanField(default=True)
    position = models.PositiveSmallIntegerField(
        default=0, help_text="Where the track comes in the simulator's catalogue."
    )

    class Meta:
        ordering = ["position", "name"]

    def __str__(self) -> str:
        return self.display_name

    @property
    def directions(self) -> list[str]:
        return [d.label for d in Direction if getattr(self, d.value)]


class RLModel(models.Model):
    """A racer's reinforcement-learning model: what a DeepRacer user calls "a model"."""

    class Status(models.TextChoices):
        QUEUED = "QUEUED", "Queued"
        TRAINING = "TRAINING", "Training"
        EVALUATING = "EVALUATING", "Evaluating"
        SUBMITTING = "SUBMITTING", "Submitting"
        STOPPING = "STOPPING", "Stopping"
        READY = "READY", "Ready"
        ERROR = "ERROR", "Error"
        IMPORTING = "IMPORTING", "Importing"
        DELETING = "DELETING", "Deleting"

    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="rl_models"
    )
    name = models.CharField(
        max_length=64,
        validators=[
            RegexValidator(
                r"^[A-Za-z0-9-]+$", "Use only letters, digits and hyphens in a model's name."
            )
        ],
    )
    description = models.CharField(max_length=255, blank=True)
    track = models.ForeignKey(Track, on_delete=models.PROTECT, related_name="rl_models")
    status = models.CharField(max_length=16, choices=Status.choices, default=Status.QUEUED)
    created_at = models.DateTimeField(auto_now_add=True)
    updated_at = models.DateTimeField(auto_now=True)

    class Meta:
        verbose_name = "model"
        ordering = ["-created_at"]
        constraints = [
            models.UniqueConstraint(fields=["owner", "name"], name="unique_model_name_per_racer")
        ]

    def __str__(self) -> str:
        return self.name


class Vehicle(models.Model):
    """A car in the racer's garage: its look and its sensors. Models are trained for a vehicle."""

    class ShellColour(models.TextChoices):
        BLACK = "#1f2328", "Black"
        WHITE = "#f5f5f5", "White"
        RED = "#d1242f", "Red"
        ORANGE = "#f28c28", "Orange"
        YELLOW = "#f2c94c", "Yellow"
        GREEN = "#2da44e", "Green"
        BLUE = "#0969da", "Blue"
        PURPLE = "#8250df", "Purple"

    class Camera(models.TextChoices):
        FRONT_FACING_CAMERA = "FRONT_FACING_CAMERA", "Single camera"
        STEREO_CAMERAS = "STEREO_CAMERAS", "Stereo cameras"

    class Lidar(models.TextChoices):
        NONE = "", "No lidar"
        SECTOR_LIDAR = "SECTOR_LIDAR", "Sector lidar (8 sectors)"
        LIDAR = "LIDAR", "Lidar (64 rays)"

    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="vehicles"
    )
    name = models.CharField(max_length=64)
    shell_colour = models.CharField(
        max_length=7, choices=ShellColour.choices, default=ShellColour.BLACK
    )
    camera = models.CharField(
        max_length=24, choices=Camera.choices, default=Camera.FRONT_FACING_CAMERA
    )
    lidar = models.CharField(max_length=16, choices=Lidar.choices, default=Lidar.NONE, blank=True)
    created_at = models.DateTimeField(auto_now_add=True)

    class Meta:
        ordering = ["name"]
        constraints = [
            models.UniqueConstraint(fields=["owner", "name"], name="unique_vehicle_name_per_racer")
        ]

    def __str__(self) -> str:
        return self.name

    @property
    def sensors(self) -> list[str]:
        """The ``sensor`` list of ``model_metadata.json``."""
        return [self.camera, self.lidar] if self.lidar else [self.camera]
