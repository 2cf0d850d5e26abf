"""A racer's models, and the tracks they train on.

Long because Django finds an app's models in one module: the training app has its tracks,
models, reward functions, vehicles, jobs, iterations, log lines, evaluations, trials and quotas.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence

import numpy as np
from django.conf import settings
from django.core.validators import MaxValueValidator, MinValueValidator, RegexValidator
from django.db import models

from rl import hyperparameters
from simulator import randomisation_ranges
from simulator import tracks as sim_tracks
from simulator.config import SPEED_RANGE


class Direction(models.TextChoices):
    COUNTERCLOCKWISE = "counterclockwise", "Counter-clockwise"
    CLOCKWISE = "clockwise", "Clockwise"


class RaceType(models.TextChoices):
    TIME_TRIAL = "TIME_TRIAL", "Time trial"
    OBJECT_AVOIDANCE = "OBJECT_AVOIDANCE", "Object avoidance"
    HEAD_TO_BOT = "HEAD_TO_BOT", "Head-to-bot"


class Network(models.TextChoices):
    SHALLOW = "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW", "3-layer CNN"
    DEEP = "DEEP_CONVOLUTIONAL_NETWORK", "5-layer CNN"


class Algorithm(models.TextChoices):
    PPO = hyperparameters.PPO, "PPO"
    SAC = hyperparameters.SAC, "SAC"


class CameraLens(models.TextChoices):
    """The camera's lens a model sees the track through (simulator.camera.LENSES)."""

    SIMULATOR = "simulator", "DeepRacer's simulated camera (64.7°)"
    WIDE = "wide", "The physical car's wide lens (120°)"


class BestCheckpointBy(models.TextChoices):
    """How training picks a model's best checkpoint: by its evaluation episodes' mean progress
    (DeepRacer's), total reward or lap time. DeepRacer for Cloud's DR_TRAIN_BEST_MODEL_METRIC
    (defaults/template-run.env:33, scripts/training/prepare-config.py:58), read by simapp as
    BEST_MODEL_METRIC (bundle/markov/metrics/constants.py:163-167, s3_metrics.py:267, 01f5f01)."""

    PROGRESS = "progress", "Progress (DeepRacer's)"
    REWARD = "reward", "Reward"
    LAPTIME = "laptime", "Lap time"


# The evaluation episodes each checkpoint drives after its update, to pick the best: simapp's
# MIN_EVAL_TRIALS (bundle/markov/rollout_worker.py:94, 328-329, 501-504, 01f5f01), DeepRacer for
# Cloud's DR_TRAIN_MIN_EVAL_TRIALS (defaults/template-run.env:32, prepare-config.py:55, 2eb1a1f).
# Ours drive beside the next iteration's training, so many more would take the update's CPU.
EVALUATION_TRIALS = 5
EVALUATION_TRIALS_RANGE = (1, 20)


class Checkpoint(models.TextChoices):
    """Which of a model's checkpoints an evaluation, a race entry, a download or a clone uses."""

    BEST = "best", "Best"  # by the model's best_checkpoint_by
    LAST = "last", "Last"


SEEDS = 2**31  # a replayable run's seed is below it: 31 bits, which every database's integer holds


def new_seed() -> int:
    """A seed for a run that is to be replayable (below ``SEEDS``)."""
    return secrets.randbelow(SEEDS)


class ShellColour(models.TextChoices):
    """A car's shell, as the garage offers it and the spectator video paints it."""

    BLACK = "#1f2328", "Black"
    WHITE = "#f5f5f5", "White"
    RED = "#d1242f", "Red"
    ORANGE = "#f28c28", "Orange"
    YELLOW = "#f2c94c", "Yellow"
    GREEN = "#2da44e", "Green"
    BLUE = "#0969da", "Blue"
    PURPLE = "#8250df", "Purple"

    @staticmethod
    def bgr(colour: str) -> tuple[int, int, int]:
        """``#rrggbb`` in OpenCV's channel order."""
        red, green, blue = (int(colour[i : i + 2], 16) for i in (1, 3, 5))
        return blue, green, red


class TrackManager(models.Manager):
    def get_queryset(self) -> models.QuerySet:
        # The route and the preview are read one track at a time (by the simulator, by the preview
        # view), never for a list: lists leave them out.
        return super().get_queryset().defer("route", "preview")


class Track(models.Model):
    """A track racers can train, evaluate and race on.

    Built-in tracks come from ``simulator.tracks``' catalogue (``manage.py loadtracks`` keeps these
    rows in step with it); tracks added by staff (``manage.py loadtracks FILE.npy --name NAME`` or
    the admin's upload) carry their DeepRacer route file and preview here, so every machine of a
    cluster reads them from the database, not from a disk it may not share.
    """

    class Difficulty(models.TextChoices):
        BEGINNER = "beginner"
        INTERMEDIATE = "intermediate"
        ADVANCED = "advanced"
        EXPERT = "expert"

    name = models.SlugField(max_length=64, unique=True, help_text="The simulator's track name.")
    display_name = models.CharField(max_length=100)
    # DeepRacer's console describes its tracks in up to 381 characters.
    description = models.CharField(max_length=500, blank=True)
    difficulty = models.CharField(max_length=16, choices=Difficulty.choices)
    length_m = models.FloatField("length [m]")
    width_m = models.FloatField("width [m]")
    counterclockwise = models.BooleanField(default=True)
    clockwise = models.BooleanField(default=True)
    default_direction = models.CharField(
        max_length=16,
        choices=Direction.choices,
        default=Direction.COUNTERCLOCKWISE,
        help_text="The direction offered first (DeepRacer's console: defaultDirection).",
    )
    season = models.PositiveSmallIntegerField(
        null=True,
        blank=True,
        help_text="The year DeepRacer raced it, as deepracer-utils' track_meta groups the tracks "
        "(2019: 2019 and earlier); empty for Pitlane's own and added tracks.",
    )
    position = models.PositiveSmallIntegerField(
        default=0, help_text="Where the track comes in the simulator's catalogue."
    )
    route = models.BinaryField(
        blank=True,
        default=b"",
        editable=False,
        help_text="The DeepRacer route file (.npy) of a track added by staff; empty when built in.",
    )
    preview = models.BinaryField(
        blank=True, default=b"", editable=False, help_text="Its top-down picture (PNG)."
    )
    added_by = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        blank=True,
        on_delete=models.SET_NULL,
        related_name="+",
    )
    added_at = models.DateTimeField(null=True, blank=True)

    objects = TrackManager()

    class Meta:
        ordering = ["position", "name"]

    def __str__(self) -> str:
        return self.display_name

    @property
    def directions(self) -> list[str]:
        return [d.label for d in Direction if getattr(self, d.value)]

    @property
    def direction_values(self) -> list[str]:
        """The directions it is driven, as stored, the default first."""
        driven = [d.value for d in Direction if getattr(self, d.value)]
        return sorted(driven, key=lambda d: d != self.default_direction)

    @property
    def season_label(self) -> str:
        """As deepracer-utils' track_meta heads its groups: "2022", "2019 and earlier"; "Pitlane"
        for our own."""
        if self.season is None:
            return "Pitlane"
        return f"{self.season} and earlier" if self.season <= 2019 else str(self.season)

    @property
    def builtin(self) -> bool:
        """Whether the track is one of the simulator's own (an added track has no ``added_at``)."""
        return self.added_at is None


class TrackLine(models.Model):
    """A track's racing line in one direction, ``margin_cm`` further inside its borders than the
    car's half width (``simulator.racing_line``): an added track's, or any track's with a margin.
    A built-in track's line without a margin is stored with the simulator and has no row.

    Computed by a worker (the ``training.racing_line`` task: 1 to 10 s of CPU, never on a
    request's thread); ``key`` is what it was computed from, and a row whose key no longer
    matches the track, the car or the method is stale and computed again."""

    # [cm] the margins a racer may ask for: up to a third of the narrowest track's half width
    # beyond the car's (DeepRacer's tracks are 0.6 to 1.07 m wide, the car 0.2 m).
    MARGINS_CM = (0, 5, 10, 15, 20)

    class Status(models.TextChoices):
        COMPUTING = "computing", "Computing"
        READY = "ready", "Ready"
        FAILED = "failed", "Failed"

    track = models.ForeignKey(Track, on_delete=models.CASCADE, related_name="lines")
    direction = models.CharField(max_length=16, choices=Direction.choices)
    margin_cm = models.PositiveSmallIntegerField(default=0)
    key = models.CharField(max_length=64, help_text="simulator.racing_line.line_key")
    status = models.CharField(max_length=16, choices=Status.choices, default=Status.COMPUTING)
    message = models.CharField(max_length=300, blank=True, help_text="Why it failed, in words.")
    points = models.BinaryField(
        default=b"", help_text="float32 rows of x, y [m] and speed [m/s], from the start line."
    )
    lap_time = models.FloatField(null=True, blank=True, help_text="[s] a flying lap.")
    standing_lap_time = models.FloatField(
        null=True, blank=True, help_text="[s] the first lap, from a standing start."
    )
    requested_at = models.DateTimeField()
    computed_at = models.DateTimeField(null=True, blank=True)

    class Meta:
        constraints = [
            models.UniqueConstraint(
                fields=["track", "direction", "margin_cm"], name="one_line_per_track_direction"
            )
        ]

    def __str__(self) -> str:
        return f"{self.track}, {self.direction}, {self.margin_cm} cm"

    @property
    def array(self) -> np.ndarray:
        """(N, 3): x, y [m] and speed [m/s] of each point."""
        return np.frombuffer(bytes(self.points), dtype=np.float32).reshape(-1, 3)


class RaceConditions(models.Model):
    """Where and how a car races, as a model trains, an evaluation drives and an event runs: the
    direction of travel and DeepRacer's race type with its obstacles (boxes) or bot cars."""

    direction = models.CharField(
        max_length=16, choices=Direction.choices, default=Direction.COUNTERCLOCKWISE
    )
    race_type = models.CharField(
        max_length=16, choices=RaceType.choices, default=RaceType.TIME_TRIAL
    )
    boxes = models.JSONField(
        null=True, blank=True, help_text='Object avoidance: {"count": 1-6, "randomize": false}.'
    )
    bots = models.JSONField(
        null=True,
        blank=True,
        help_text='Head-to-bot: {"count": 1-6, "speed": 0.2-6, "lane_changes": false}.',
    )

    class Meta:
        abstract = True


class RLModel(RaceConditions):
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

    DELETABLE = (Status.READY, Status.ERROR)  # nothing runs on the model

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

    # The training configuration, in the vocabulary of DeepRacer's model_metadata.json.
    sensors = models.JSONField(default=list)
    network = models.CharField(max_length=40, choices=Network.choices, default=Network.SHALLOW)
    network_layout = models.PositiveSmallIntegerField(
        default=hyperparameters.NETWORK_LAYOUT,
        help_text="2: DeepRacer's networks, layer for layer; 1: Pitlane's own, before (its weights "
        "are for those).",
    )
    action_space_type = models.CharField(
        max_length=10,
        choices=[("discrete", "Discrete"), ("continuous", "Continuous")],
        default="discrete",
    )
    action_space = models.JSONField(default=list)
    algorithm = models.CharField(max_length=16, choices=Algorithm.choices, default=Algorithm.PPO)
    hyperparameters = models.JSONField(default=dict)
    max_minutes = models.PositiveIntegerField("maximum training time [min]", default=60)
    reward_function = models.TextField(blank=True)
    workers = models.PositiveSmallIntegerField("simulation workers", default=1)
    extra_tracks = models.JSONField(
        default=list, blank=True, help_text="More tracks to train on, one per extra worker."
    )
    seed = models.IntegerField(default=0)
    best_checkpoint_by = models.CharField(
        max_length=8,
        choices=BestCheckpointBy.choices,
        default=BestCheckpointBy.PROGRESS,
        help_text="How training picks the best checkpoint (DR_TRAIN_BEST_MODEL_METRIC).",
    )
    evaluation_trials = models.PositiveSmallIntegerField(
        default=EVALUATION_TRIALS,
        help_text="The evaluation episodes each checkpoint drives to pick the best "
        "(DR_TRAIN_MIN_EVAL_TRIALS).",
    )
    world_name = models.CharField(
        max_length=64,
        blank=True,
        help_text="The track's DeepRacer route file it drives, by WORLD_NAME, where that is not "
        "the one the console drives its direction: a DeepRacer for Cloud model's bare "
        "WORLD_NAME (simulator.tracks.Track.on_route). Blank: the console's.",
    )
    cloned_from = models.ForeignKey(
        "self", null=True, blank=True, on_delete=models.SET_NULL, related_name="clones"
    )
    cloned_checkpoint = models.CharField(
        max_length=8,
        blank=True,
        help_text="A clone's start: its source's best or last checkpoint (a Checkpoint), or the "
        "number of the iteration whose checkpoint it is.",
    )
    vehicle = models.ForeignKey(
        "Vehicle", null=True, blank=True, on_delete=models.SET_NULL, related_name="rl_models"
    )
    shell_colour = models.CharField(
        max_length=7,
        choices=ShellColour.choices,
        default=ShellColour.BLACK,
        help_text="The car's colour in the video: its vehicle's when it was created.",
    )
    camera_lens = models.CharField(
        max_length=10,
        choices=CameraLens.choices,
        default=CameraLens.SIMULATOR,
        help_text="DeepRacer's simulated camera, as its console trained with, or the physical "
        "car's wide lens, for a model meant for a car.",
    )
    camera_before_deepracer = models.BooleanField(
        default=False,
        editable=False,
        help_text="Trained on this console before issue 44 gave the car DeepRacer's camera "
        "(migration 0018): it learnt Pitlane's 120°, 25° down view, and now drives with the "
        "64.7° one.",
    )
    lidar_before_deepracer = models.BooleanField(
        default=False,
        editable=False,
        help_text="Trained with a lidar on this console before issue 44 put it on simapp's "
        "mount (migration 0022): it learnt a lidar facing forwards 0.1 m up, and now reads one "
        "facing backwards 0.182 m up.",
    )
    domain_randomisation = models.BooleanField(
        default=False,
        help_text=f"Each episode in a scene of its own: {randomisation_ranges.SUMMARY} "
        "(simulator.randomisation); DeepRacer for Cloud's DR_ENABLE_DOMAIN_RANDOMIZATION.",
    )
    import_notes = models.JSONField(
        default=list,
        blank=True,
        help_text="What an import rebuilt or left out, in a racer's words: shown on the model's "
        "page for as long as the model lives.",
    )

    class Meta:
        verbose_name = "model"
        ordering = ["-created_at"]
        constraints = [
            models.UniqueConstraint(fields=["owner", "name"], name="unique_model_name_per_racer")
        ]

    def __str__(self) -> str:
        return self.name

    def route_on(self, track: str | None = None) -> str | None:
        """The route file (a WORLD_NAME) it drives ``track`` on: on its own track (None), its
        ``world_name``, simapp's file for an import's bare WORLD_NAME (simapp
        bundle/markov/track_geom/track_data.py:194-198 loads routes/<WORLD_NAME>.npy, 01f5f01);
        None for the console's file, as on any other track."""
        own = track in (None, self.track.name)
        return (self.world_name or None) if own else None

    def driven_track(
        self, track: str | None = None, direction: str | None = None
    ) -> sim_tracks.Track:
        """The track as this model drives it, and so as it drove it: its own (or ``track``,
        an evaluation's) ``direction`` (its own when None), on ``route_on``'s file. Everything
        that replays its driving (the Analysis map, re-scoring, ``simulator.params.replayed``)
        reads this, so that its steps lie on the route they were driven on."""
        name = track or self.track.name
        return sim_tracks.driven(name, direction or self.direction, self.route_on(name))

    @property
    def cloned_checkpoint_words(self) -> str:
        """Which of its source's checkpoints this clone started from, in words."""
        which = self.cloned_checkpoint
        return (
            f"the checkpoint of its iteration {which}"
            if which.isdigit()
            else f"its {which} checkpoint"
        )

    def environment_settings(self, track: str | None = None) -> dict:
        """The keyword arguments of ``gymnasium.make("Pitlane/DeepRacer-v0", ...)``; on another
        ``track`` than its own, that track's route for the direction (``route_on``). Each
        setting's argument is declared with the setting (``training.configuration``)."""
        from training.configuration import environment_of  # which imports these models

        return {
            **environment_of(self),
            "track": track or self.track.name,
            "route": self.route_on(track),
        }

    @property
    def trainable(self) -> bool:
        """Whether the model can train on (be cloned): not one imported from a car archive, which
        brings its policy alone, with no reward function."""
        return bool(self.reward_function.strip())

    @property
    def architecture(self) -> str:
        """What builds the model's network (``rl.networks.architecture``)."""
        from rl.networks import architecture  # torch: imported where networks are built

        return architecture(self.network, self.network_layout)

    def metadata(self) -> dict:
        """DeepRacer's model_metadata.json."""
        return {
            "action_space": self.action_space,
            "action_space_type": self.action_space_type,
            "sensor": list(self.sensors),
            "neural_network": self.network,
            "training_algorithm": self.algorithm,
            "version": "5",
        }

    @property
    def latest_job(self) -> TrainingJob | None:
        return self.jobs.order_by("-created_at").first()

    @property
    def extra_track_names(self) -> list[str]:
        """The extra tracks' names as racers read them, in the order chosen."""
        names = dict(
            Track.objects.filter(name__in=self.extra_tracks).values_list("name", "display_name")
        )
        return [names.get(name, name) for name in self.extra_tracks]


class RewardFunction(models.Model):
    """A named reward function in the racer's library, picked when a model is created."""

    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="reward_functions"
    )
    name = models.CharField(max_length=64)
    source = models.TextField()
    created_at = models.DateTimeField(auto_now_add=True)
    updated_at = models.DateTimeField(auto_now=True)

    class Meta:
        ordering = ["name"]
        constraints = [
            models.UniqueConstraint(
                fields=["owner", "name"], name="unique_reward_function_name_per_racer"
            )
        ]

    def __str__(self) -> str:
        return self.name


class Vehicle(models.Model):
    """A car in the racer's garage: its look and its sensors. Models are trained for a vehicle."""

    ShellColour = ShellColour

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


class TrainingJob(models.Model):
    """One training run of a model: DeepRacer's job states, and the lease that keeps it single."""

    class Status(models.TextChoices):
        QUEUED = "QUEUED", "Queued"
        INITIALIZING = "INITIALIZING", "Initializing"
        IN_PROGRESS = "IN_PROGRESS", "In progress"
        STOPPING = "STOPPING", "Stopping"
        COMPLETED = "COMPLETED", "Completed"
        FAILED = "FAILED", "Failed"
        CANCELED = "CANCELED", "Canceled"

    ACTIVE = (Status.QUEUED, Status.INITIALIZING, Status.IN_PROGRESS, Status.STOPPING)

    model = models.ForeignKey(RLModel, on_delete=models.CASCADE, related_name="jobs")
    status = models.CharField(max_length=16, choices=Status.choices, default=Status.QUEUED)
    created_at = models.DateTimeField(auto_now_add=True)
    started_at = models.DateTimeField(null=True, blank=True)
    finished_at = models.DateTimeField(null=True, blank=True)
    stop_requested = models.BooleanField(default=False)
    failure_reason = models.TextField(blank=True)
    message = models.CharField(max_length=255, blank=True, help_text="What the racer sees now.")
    # The lease: the trainer run that holds it renews it; only the holder (by attempt) may write.
    attempt = models.PositiveIntegerField(default=0)
    lease_owner = models.CharField(max_length=255, blank=True)
    lease_expires = models.DateTimeField(null=True, blank=True)
    # Progress
    weights_version = models.PositiveIntegerField(default=0)
    iterations = models.PositiveIntegerField(default=0)
    episodes = models.PositiveIntegerField(default=0)
    steps = models.PositiveBigIntegerField(default=0)
    training_seconds = models.FloatField(default=0.0)
    clock_at = models.DateTimeField(
        null=True,
        blank=True,
        help_text="When training_seconds was measured: the live clock's origin.",
    )
    last_checkpoint = models.CharField(max_length=255, blank=True)
    best_checkpoint = models.CharField(max_length=255, blank=True)

    class Meta:
        ordering = ["created_at"]
        indexes = [models.Index(fields=["status", "created_at"])]

    def __str__(self) -> str:
        return f"{self.model} training #{self.pk}"

    @property
    def is_active(self) -> bool:
        return self.status in self.ACTIVE


class Iteration(models.Model):
    """One policy update and what it was learnt from, with the evaluation that followed it."""

    job = models.ForeignKey(TrainingJob, on_delete=models.CASCADE, related_name="iteration_rows")
    number = models.PositiveIntegerField()
    reward = models.FloatField(help_text="Average reward per training episode.")
    completion = models.FloatField(help_text="Average progress [%] of the training episodes.")
    evaluation_completion = models.FloatField(null=True, blank=True)
    best_lap_time = models.FloatField(null=True, blank=True, help_text="[s], when a lap was done.")
    episodes = models.PositiveIntegerField()
    steps = models.PositiveIntegerField()
    wall_seconds = models.FloatField(
        help_text="[s] from the end of the previous iteration (or the start) to this one's end."
    )
    time_split = models.JSONField(
        default=dict,
        help_text="[s] of the wall time by phase (rl.stopwatch.PHASES); they add up to it.",
    )
    evaluation_seconds = models.FloatField(
        null=True,
        blank=True,
        help_text="[s] the evaluation of this iteration's checkpoint took, beside the next one.",
    )
    training_points = models.JSONField(
        default=list, help_text="[reward, progress %] of each training episode, for the graph."
    )
    evaluation_points = models.JSONField(
        default=list, help_text="Progress [%] of each evaluation episode, for the graph."
    )
    evaluation_reward = models.FloatField(
        null=True, blank=True, help_text="Mean total reward of the evaluation episodes."
    )
    evaluation_lap_ms = models.FloatField(
        null=True,
        blank=True,
        help_text="[ms] mean lap time of the evaluation episodes, 999999 for each unfinished "
        "one (DeepRacer's best-model lap time).",
    )
    created_at = models.DateTimeField(auto_now_add=True)

    class Meta:
        ordering = ["job", "number"]
        constraints = [
            models.UniqueConstraint(fields=["job", "number"], name="one_row_per_iteration")
        ]

    def __str__(self) -> str:
        return f"{self.job}, iteration {self.number}"

    @property
    def best_lap_ms(self) -> int | None:
        return None if self.best_lap_time is None else round(self.best_lap_time * 1000)


class JobLogLine(models.Model):
    """The job's log, as the racer reads it on the model page."""

    class Source(models.TextChoices):
        TRAINER = "trainer", "Trainer"
        WORKER = "worker", "Simulation worker"
        REWARD = "reward", "Reward function"

    job = models.ForeignKey(TrainingJob, on_delete=models.CASCADE, related_name="log_lines")
    at = models.DateTimeField(auto_now_add=True)
    level = models.CharField(max_length=8, default="info")
    source = models.CharField(max_length=8, choices=Source.choices, default=Source.TRAINER)
    text = models.CharField(max_length=500)

    class Meta:
        ordering = ["at", "pk"]

    def __str__(self) -> str:
        return self.text


class EvaluationJob(RaceConditions):
    """An evaluation of a ready model (DeepRacer's "Evaluate"): the policy drives the chosen
    track deterministically for a number of trials, under race rules. No racer code runs: the
    policy is loaded from its weights only, and the reward function is not used."""

    Status = TrainingJob.Status
    ACTIVE = TrainingJob.ACTIVE

    Checkpoint = Checkpoint

    model = models.ForeignKey(RLModel, on_delete=models.CASCADE, related_name="evaluations")
    track = models.ForeignKey(Track, on_delete=models.PROTECT, related_name="evaluations")
    trials = models.PositiveSmallIntegerField(default=3)
    continuous_laps = models.BooleanField(
        default=False, help_text="Drive the trials as consecutive laps, without stopping."
    )
    off_track_penalty = models.FloatField("off-track penalty [s]", default=2.0)
    crash_penalty = models.FloatField("crash penalty [s]", default=5.0)
    max_resets = models.PositiveSmallIntegerField(
        "resets allowed",
        null=True,
        blank=True,
        help_text="Times the car may be put back on the track before its trial ends there "
        "(DeepRacer for Cloud's DR_EVAL_MAX_RESETS); empty: no limit, as in a race.",
    )
    checkpoint = models.CharField(max_length=8, choices=Checkpoint.choices, default=Checkpoint.BEST)
    checkpoint_name = models.CharField(max_length=255, blank=True, help_text="The weights used.")
    checkpoint_iteration = models.PositiveIntegerField(
        null=True, blank=True, help_text="The training iteration whose weights were used."
    )
    domain_randomisation = models.BooleanField(
        default=False, help_text="Each trial in a randomised scene, whatever the model trained in."
    )
    seed = models.PositiveIntegerField(
        null=True,
        blank=True,
        default=new_seed,
        help_text="Seeds its trials' noise; the same seed drives them again exactly. Empty: "
        "driven without noise (before seeds).",
    )
    speed_multiplier = models.FloatField(
        default=1.0,
        help_text="Each action's speed times this: a live race's racer's choice, "
        "as DeepRacer's LIVE races let racers drive at 0.5-1.5 times their model's speeds.",
    )
    real_time = models.BooleanField(
        default=False,
        help_text="Driven at the speed of real time even when nobody watches: "
        "a live race's turn, which its audience sees as it happens.",
    )
    # Model against model: the cars of one race are evaluations driven together by the run of
    # the first (its ``grid_leader``, None), each of its own model with its own trials, trace and
    # video, as DeepRacer for Cloud's head-to-model evaluation writes each model's files under
    # its own prefix (scripts/evaluation/prepare-config.py:119-143, deepracer-for-cloud).
    grid_leader = models.ForeignKey(
        "self",
        null=True,
        blank=True,
        on_delete=models.SET_NULL,
        related_name="grid",
        help_text="The first car of the race this car drove in; empty for the first or alone.",
    )
    grid_position = models.PositiveSmallIntegerField(
        default=0, help_text="Its place on the grid: 0 in front, each next car 0.75 m behind."
    )
    rival = models.BooleanField(
        default=False,
        help_text="Another racer's model raced against this one's: its model was "
        "not reserved, and its owner is not told.",
    )
    status = models.CharField(max_length=16, choices=Status.choices, default=Status.QUEUED)
    message = models.CharField(max_length=255, blank=True)
    failure_reason = models.TextField(blank=True)
    video = models.CharField(max_length=255, blank=True, help_text="Storage name of the video.")
    created_at = models.DateTimeField(auto_now_add=True)
    started_at = models.DateTimeField(null=True, blank=True)
    finished_at = models.DateTimeField(null=True, blank=True)
    # The run driving it renews this while it drives (``training.leases.lapsed_evaluations``).
    lease_owner = models.CharField(max_length=255, blank=True)
    lease_expires = models.DateTimeField(null=True, blank=True)

    class Meta:
        ordering = ["-created_at"]

    def __str__(self) -> str:
        return f"{self.model} evaluation #{self.pk}"

    @property
    def is_active(self) -> bool:
        return self.status in self.ACTIVE

    @property
    def completed_trials(self) -> int:
        return sum(trial.completed for trial in self.trial_rows.all())

    @property
    def best_lap_ms(self) -> int | None:
        laps = [trial.time_ms for trial in self.trial_rows.all() if trial.completed]
        return min(laps) if laps else None

    @property
    def laps(self) -> int:
        """Laps per episode: all the trials in one with continuous laps, else one."""
        return self.trials if self.continuous_laps else 1

    def environment_settings(self, race: Sequence[EvaluationJob] = ()) -> dict:
        """The evaluation's ``gymnasium.make`` keyword arguments; in a ``race`` of several cars
        (this one among them, in grid order), its place on the grid and the others' colours."""
        together = {}
        if len(race) > 1:
            together = {
                "rivals": len(race) - 1,
                "grid": [car.pk for car in race].index(self.pk),
                "rival_colours": [
                    ShellColour.bgr(car.model.shell_colour) for car in race if car.pk != self.pk
                ],
            }
        return {
            **self.model.environment_settings(self.track.name),
            "direction": self.direction,
            "race_type": self.race_type,
            "objects": self.boxes,
            "bots": self.bots,
            "mode": "evaluation",
            "laps": self.laps,
            "penalties": {"off_track": self.off_track_penalty, "crash": self.crash_penalty},
            "max_resets": self.max_resets,
            "noise": self.seed is not None,
            "randomise": self.domain_randomisation,
            "action_space": scaled_speeds(self.model.action_space, self.speed_multiplier),
            **together,
        }

    def driven_track(self) -> sim_tracks.Track:
        """The track as this evaluation drives it (``RLModel.driven_track``): its model's route
        file on the model's own track, the console's on another."""
        return self.model.driven_track(self.track.name, self.direction)

    def trial_seed(self, number: int) -> int | None:
        """The seed of the episode of trial ``number`` (0 on; continuous laps drive one):
        drawn from the evaluation's, so that trials differ."""
        if self.seed is None:
            return None
        state = np.random.SeedSequence([self.seed, number]).generate_state(1)
        return int(state[0]) & 0x7FFFFFFF


class EvaluationTrial(models.Model):
    """One trial of an evaluation: a lap, or as much of one as the car drove."""

    # What the statuses say on pages and in DeepRacer's metrics (the live table gets the same
    # words through ``selectors.trial_row``).
    STATUS_LABELS = {"lap_complete": "Lap complete", "time_up": "Time up"}

    evaluation = models.ForeignKey(
        EvaluationJob, on_delete=models.CASCADE, related_name="trial_rows"
    )
    number = models.PositiveSmallIntegerField()
    time_ms = models.PositiveIntegerField(help_text="Simulated time, penalties included.")
    progress = models.FloatField(help_text="[%] of the lap.")
    status = models.CharField(max_length=20)
    off_tracks = models.PositiveIntegerField(default=0)
    crashes = models.PositiveIntegerField(default=0)
    resets = models.PositiveIntegerField(default=0)
    penalty_ms = models.PositiveIntegerField(default=0)
    seed = models.PositiveIntegerField(
        null=True, blank=True, help_text="The seed of the episode it was driven in."
    )

    class Meta:
        ordering = ["evaluation", "number"]
        constraints = [
            models.UniqueConstraint(fields=["evaluation", "number"], name="one_row_per_trial")
        ]

    def __str__(self) -> str:
        return f"{self.evaluation}, trial {self.number}"

    @property
    def completed(self) -> bool:
        return self.status == "lap_complete"

    @property
    def status_display(self) -> str:
        return self.STATUS_LABELS.get(self.status, self.status.replace("_", " ").capitalize())


MOST_MACHINE_SHARE = 8  # a racer's share of the machine: 1 (everyone's) to this


class QuotaDefaults(models.Model):
    """What new racers get (one row, edited by staff in the admin): DeepRacer on AWS limited
    models per account and training hours per month."""

    max_models = models.PositiveIntegerField("models", default=20)
    max_minutes_per_month = models.PositiveIntegerField("training minutes per month", default=600)

    class Meta:
        verbose_name = verbose_name_plural = "quota for new racers"

    def __str__(self) -> str:
        return f"{self.max_models} models, {self.max_minutes_per_month} min/month"

    @classmethod
    def current(cls) -> QuotaDefaults:
        return cls.objects.get_or_create(pk=1)[0]


class Quota(models.Model):
    """A racer's limits, set from the defaults when they sign up; staff may change them."""

    racer = models.OneToOneField(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="quota"
    )
    max_models = models.PositiveIntegerField("models")
    max_minutes_per_month = models.PositiveIntegerField("training minutes per month")
    machine_share = models.PositiveSmallIntegerField(
        "share of the machine",
        default=1,
        validators=[MinValueValidator(1), MaxValueValidator(MOST_MACHINE_SHARE)],
        help_text=(
            "Each of this racer's trainings takes this many shares of the machine's cores "
            "against the others training at the same time: 2 is twice what a racer at 1 gets."
        ),
    )

    def __str__(self) -> str:
        return f"{self.racer}: {self.max_models} models, {self.max_minutes_per_month} min/month"

    @classmethod
    def of(cls, racer) -> Quota:
        defaults = QuotaDefaults.current()
        return cls.objects.get_or_create(
            racer=racer,
            defaults={
                "max_models": defaults.max_models,
                "max_minutes_per_month": defaults.max_minutes_per_month,
            },
        )[0]


def top_speed(action_space) -> float:
    """The fastest speed [m/s] of ``action_space`` (DeepRacer's discrete list or continuous
    ranges)."""
    if isinstance(action_space, dict):
        return float(action_space["speed"]["high"])
    return max(float(action["speed"]) for action in action_space)


def scaled_speeds(action_space, multiplier: float):
    """``action_space`` (DeepRacer's: a list of discrete actions, or continuous ranges) with every
    speed times ``multiplier``, kept within the car's 0.1-4 m/s; itself when that is 1."""
    if multiplier == 1.0:
        return action_space
    low, high = SPEED_RANGE

    def scaled(speed: float) -> float:
        return min(max(speed * multiplier, low), high)

    if isinstance(action_space, dict):
        speed = action_space["speed"]
        return {**action_space, "speed": {key: scaled(value) for key, value in speed.items()}}
    return [{**action, "speed": scaled(action["speed"])} for action in action_space]
