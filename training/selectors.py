"""Reads for the training app.

Long because the app's reads are kept in one module, as its writes are in services.py: models
and their training, tracks, vehicles, checkpoints (and what counts as trained), evaluations,
races, quotas and reward functions.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime

import redis
from django.contrib.auth.models import AbstractBaseUser
from django.core.files.storage import default_storage
from django.db.models import Count, F, FloatField, Prefetch, Q, QuerySet, Sum
from django.db.models.functions import Least, Lower
from django.shortcuts import get_object_or_404
from django.utils import timezone

from accounts.selectors import racer_name
from common.redis_client import redis_client
from rl.experience import JobChannel
from rl.stopwatch import PHASES
from training import artifacts, leases, track_lines
from training.leases import IMPORTED
from training.models import (
    BestCheckpointBy,
    EvaluationJob,
    EvaluationTrial,
    Iteration,
    JobLogLine,
    Quota,
    RewardFunction,
    RLModel,
    Track,
    TrainingJob,
    Vehicle,
)


def models_for_racer(*, racer: AbstractBaseUser) -> QuerySet[RLModel]:
    return RLModel.objects.filter(owner=racer).select_related("track")


def models_with_training(*, racer: AbstractBaseUser) -> list[RLModel]:
    """The racer's models, each with ``training``: its latest job (or None) and, on that job,
    ``queue_position`` (None unless it waits), ``imported_only`` and ``clock``; and
    ``status_text``, its status in words (``model_status_display``): two queries, and one per
    waiting job."""
    now = timezone.now()
    newest_first = TrainingJob.objects.order_by("-created_at")
    models = list(
        models_for_racer(racer=racer).prefetch_related(
            Prefetch("jobs", queryset=newest_first, to_attr="jobs_newest_first")
        )
    )
    free = None  # trainers, counted once and only when a job waits
    for model in models:
        model.training = model.jobs_newest_first[0] if model.jobs_newest_first else None
        saved = [job.last_checkpoint for job in model.jobs_newest_first if job.last_checkpoint]
        model.status_text = model_status_display(
            model=model,
            untrained=model_untrained(model=model, last_checkpoint=saved[0] if saved else ""),
        )
        if model.training is not None:
            model.training.imported_only = job_imported_only(job=model.training)
            model.training.queue_position = leases.queue_position(model.training)
            if model.training.queue_position is not None:
                free = leases.trainers_free() if free is None else free
                model.training.queue_words = queue_words(job=model.training, free=free)
            model.training.clock = training_clock(job=model.training, now=now)
    return models


def queue_words(*, job: TrainingJob, free: int | None = None) -> str:
    """Where ``job`` stands in the queue, in the racer's words: starting, while a trainer is free
    for it (``free``, the trainers holding no job, counted when not given), else its place and
    that it waits for a free trainer; for a job that trains, whom it shares the machine with
    (``sharing_words``)."""
    place = leases.queue_position(job)
    if place is None:
        return sharing_words(job=job)
    if place <= (leases.trainers_free() if free is None else free):
        return "starting on a free trainer"
    return f"number {place} in the queue, waiting for a free trainer"


def model_of_racer(*, racer: AbstractBaseUser, pk: int) -> RLModel:
    """The racer's own model ``pk``, or 404: the one access check of every page of a model."""
    return get_object_or_404(RLModel.objects.select_related("track"), pk=pk, owner=racer)


def sharing_words(*, job: TrainingJob) -> str:
    """While ``job`` trains beside others (each holding a trainer of its own and its rollout
    workers, the machine's cores shared among them all by their racers' shares, jobs.shares),
    how many and its share, in the racer's words; "" when it trains alone or does not train."""
    if job.status not in (TrainingJob.Status.INITIALIZING, TrainingJob.Status.IN_PROGRESS):
        return ""
    shares = leases.machine_shares(leases.jobs_holding_trainers())
    mine = shares.pop(job.pk, 1)
    if not shares:
        return ""
    trainings = "1 other training" if len(shares) == 1 else f"{len(shares)} other trainings"
    if all(share == mine for share in shares.values()):
        return f"sharing the machine with {trainings}, each taking an equal share"
    total = mine + sum(shares.values())
    return f"sharing the machine with {trainings}, taking {mine} of {total} shares"


def job_imported_only(*, job: TrainingJob | None) -> bool:
    """Whether ``job`` is only an import's record, without training history: the model was
    trained elsewhere (or is a car archive's policy), so it has no training clock, iteration or
    episode to show, and never had this console's training time."""
    return job is not None and job.lease_owner == IMPORTED and not job.iterations


def tracks_available() -> QuerySet[Track]:
    return Track.objects.all()


# The track picker's orders (static/training/track_picker.js sorts the same way in the page):
# the catalogue's, by name, by length or width (shortest, narrowest first), by season (newest
# first, Pitlane's own before DeepRacer's).
TRACK_SORTS = {
    "": ("position", "name"),
    "name": (Lower("display_name"), "name"),
    "length": ("length_m", "position"),
    "width": ("width_m", "position"),
    "season": (F("season").desc(nulls_first=True), "position"),
}


def tracks_listed(*, search: str = "", sort: str = "") -> QuerySet[Track]:
    """The tracks whose display name, name (DeepRacer's WORLD_NAME) or season holds every word of
    ``search``, in the order ``sort`` names (one of ``TRACK_SORTS``; another is the catalogue's)."""
    tracks = Track.objects.all()
    for word in search.split():
        matches = Q(display_name__icontains=word) | Q(name__icontains=word)
        if word.isdigit():
            matches |= Q(season=int(word))
        elif "pitlane".startswith(word.lower()):
            matches |= Q(season__isnull=True)
        tracks = tracks.filter(matches)
    return tracks.order_by(*TRACK_SORTS.get(sort, TRACK_SORTS[""]))


def track_named(*, name: str) -> Track:
    """The track called ``name``, or 404."""
    return get_object_or_404(Track, name=name)


def track_added_preview(*, name: str) -> bytes | None:
    """The stored preview (PNG) of the track staff added under ``name``, or None where there is
    none (a built-in track's is the simulator's file)."""
    row = Track.objects.filter(name=name, added_at__isnull=False).values("preview").first()
    return bytes(row["preview"]) if row and row["preview"] else None


def vehicles_for_racer(*, racer: AbstractBaseUser) -> QuerySet[Vehicle]:
    return Vehicle.objects.filter(owner=racer)


def vehicles_in_garage(*, racer: AbstractBaseUser) -> QuerySet[Vehicle]:
    """The racer's vehicles, each with ``model_count``: how many models were trained on it."""
    return vehicles_for_racer(racer=racer).annotate(model_count=Count("rl_models"))


@dataclass(frozen=True)
class ModelFile:
    relative: str
    label: str


def model_files(*, model: RLModel) -> list[ModelFile]:
    """The model's downloadable logs: the metrics JSON and each iteration's simulation trace."""
    files = []
    prefix = artifacts.path(model, "")
    if default_storage.exists(prefix + artifacts.TRAINING_METRICS):
        files.append(ModelFile(artifacts.TRAINING_METRICS, "Training metrics (JSON)"))
    try:
        _, names = default_storage.listdir(prefix + "training-simtrace")
    except FileNotFoundError:
        names = []
    iterations = sorted(int(n.split("-")[0]) for n in names if n.split("-")[0].isdigit())
    for number in iterations:
        relative = f"training-simtrace/{number}-iteration.csv"  # counted from 0, as DeepRacer's
        files.append(ModelFile(relative, f"Simulation trace, iteration {number + 1}"))
    return files


@dataclass(frozen=True)
class TrainingClock:
    """A training job's clock at one moment (``at``, the server's time): the time it has used,
    whether that still grows, and its limit. Every page, the live stream and the quota read it
    from the same origin (``TrainingJob.training_seconds`` measured at ``clock_at``), so they
    agree to the second."""

    seconds: float  # [s] used at ``at``
    at: datetime
    running: bool
    max_seconds: int

    @property
    def left(self) -> float:
        return max(self.max_seconds - self.seconds, 0.0)

    def as_dict(self) -> dict:
        """What the page's clock counts from: the time used at the server's ``server_now``."""
        return {
            "seconds_used": round(self.seconds, 3),
            "server_now": round(self.at.timestamp(), 3),
            "clock_running": self.running,
            "max_seconds": self.max_seconds,
        }


def training_clock(*, job: TrainingJob, now: datetime | None = None) -> TrainingClock:
    """The job's clock ``now``: the trainer's last measurement, plus the time since it while the
    job trains. It stops once the racer asks to stop (the time up to the request is what is
    billed) and at the time limit."""
    now = now or timezone.now()
    max_seconds = job.model.max_minutes * 60
    seconds = job.training_seconds
    running = (
        job.status == TrainingJob.Status.IN_PROGRESS
        and not job.stop_requested
        and job.clock_at is not None
    )
    if running:
        seconds += max((now - job.clock_at).total_seconds(), 0.0)
    return TrainingClock(
        seconds=min(seconds, max_seconds),
        at=now,
        running=running and seconds < max_seconds,
        max_seconds=max_seconds,
    )


LOG_SHOWN = 200  # lines of a job's log its model page shows; the download has them all


def job_log(*, job: TrainingJob, source: str = "") -> list[JobLogLine]:
    """The newest ``LOG_SHOWN`` lines of the job's log in time order, oldest first, as the
    download has them; only those of ``source`` (trainer, worker, reward) when it is given."""
    lines = job.log_lines.all()
    if source:
        lines = lines.filter(source=source)
    return list(reversed(lines.order_by("-at", "-pk")[:LOG_SHOWN]))


def model_log_lines(*, model: RLModel) -> Iterator[str]:
    """The whole log of the model's training, oldest first, as lines of text: the time in the
    racer's zone, who wrote the line, and what it says."""
    sources = dict(JobLogLine.Source.choices)
    yield f"Training log of {model.name}; times in {timezone.get_current_timezone_name()}\n"
    lines = JobLogLine.objects.filter(job__model=model).order_by("job__created_at", "at", "pk")
    for line in lines.iterator(chunk_size=2000):
        when = timezone.localtime(line.at).strftime("%Y-%m-%d %H:%M:%S")
        level = "" if line.level == "info" else f" {line.level.upper()}:"
        yield f"{when}  [{sources.get(line.source, line.source)}]{level} {line.text}\n"


def training_status(*, job: TrainingJob) -> dict:
    """A training job's state as the live page shows it (a ``status`` message)."""
    model = job.model
    return {
        **training_clock(job=job).as_dict(),
        "type": "status",
        "status": job.status,
        "status_display": job.get_status_display(),
        "active": job.is_active,
        "message": job.message,
        "failure_reason": job.failure_reason,
        "queue_position": leases.queue_position(job),
        "queue_words": queue_words(job=job),
        "iterations": job.iterations,
        "episodes": job.episodes + episodes_arrived(job=job),
        "steps": job.steps,
        "model_status": model.status,
        "model_status_display": model_status_display(model=model),
        "workers": model.workers,
    }


def episodes_arrived(*, job: TrainingJob) -> int:
    """The episodes of the iteration under way that have come so far: the rollout workers push
    each to the job's buffer as its car ends it, counted by the weights it was driven with
    (``JobChannel.counts``), and the trainer learns from the newest weights' first
    ``num_episodes_between_training``. So the page counts an episode as the video shows it end,
    not only once its iteration is learnt; 0 for a job that does not train now (a stopped
    job's episodes never learnt are not counted) or when Redis cannot say."""
    if job.status not in (TrainingJob.Status.INITIALIZING, TrainingJob.Status.IN_PROGRESS):
        return 0
    try:
        with redis_client() as client:
            pushed = int(client.hget(JobChannel(client, job.pk).counts, job.weights_version) or 0)
    except (redis.RedisError, ValueError):
        return 0
    return min(pushed, job.model.hyperparameters["num_episodes_between_training"])


def iteration_point(*, row: Iteration) -> dict:
    """One iteration for the live graph (an ``iteration`` message)."""
    return {
        "type": "iteration",
        "number": row.number,
        "reward": row.reward,
        "completion": row.completion,
        "evaluation_completion": row.evaluation_completion,
        "best_lap_time": row.best_lap_time,
        "episodes": row.episodes,
        "steps": row.steps,
        "training_points": row.training_points,
        "evaluation_points": row.evaluation_points,
        "wall_seconds": row.wall_seconds,
        "time_split": time_split(row=row),
        "evaluation_seconds": row.evaluation_seconds,
    }


def time_split(*, row: Iteration) -> list[dict]:
    """Where the iteration's wall time went, phase by phase, in the racer's words: ``phase``,
    ``label``, ``seconds`` and ``share`` of the wall time [%]. Empty for an iteration recorded
    without it (imported, or trained before the split was kept)."""
    if not row.time_split or row.wall_seconds <= 0:
        return []
    return [
        {
            "phase": phase,
            "label": label,
            "seconds": row.time_split.get(phase, 0.0),
            "share": round(100 * row.time_split.get(phase, 0.0) / row.wall_seconds, 1),
        }
        for phase, label in PHASES.items()
    ]


def training_snapshot(*, job: TrainingJob) -> dict:
    """Everything a viewer who connects needs at once: the status and every iteration so far."""
    return {
        **training_status(job=job),
        "type": "state",
        "history": [iteration_point(row=row) for row in job.iteration_rows.all()],
    }


def _newest_trained_job(model: RLModel) -> TrainingJob | None:
    """The model's newest training that saved a checkpoint."""
    return (
        TrainingJob.objects.filter(model=model)
        .exclude(last_checkpoint="")
        .order_by("-created_at")
        .first()
    )


def model_checkpoint(*, model: RLModel, which: str = "best") -> str | None:
    """The storage name of the model's ``best`` or ``last`` checkpoint, from its newest training
    that saved one; None when it has none."""
    job = _newest_trained_job(model)
    return None if job is None else _checkpoint_of(job, which)


def _checkpoint_of(job: TrainingJob, which: str) -> str:
    best = job.best_checkpoint if which == "best" else ""
    if best and artifacts.checkpoint_iteration(best) == 0:
        # The weights training started from stand for the best only until an iteration's
        # evaluation comes in (iteration 0 is never evaluated): a job stopped before that has
        # the last iteration's as its best, as nothing was measured better.
        best = ""
    return best or job.last_checkpoint


UNTRAINED = "not trained yet (stopped before its first policy update)"


def checkpoint_trained(*, model: RLModel, name: str) -> bool:
    """Whether the stored checkpoint ``name`` of ``model`` holds trained weights: the one
    definition of "trained" that races, downloads, clones and the model's status go by.

    Weights saved after a policy update (iteration 1 on) are trained, and so are those an import
    brought and a clone's starting weights (its source's best or last, as the clone chose). The
    weights a new model starts from (iteration 0) are not: a model stopped before its first
    policy update has only those, random ones."""
    if artifacts.checkpoint_iteration(name) != 0:
        return True
    return default_storage.exists(artifacts.path(model, artifacts.CLONED_WEIGHTS))


def model_trained_checkpoint(*, model: RLModel, which: str = "best") -> str | None:
    """The model's ``which`` checkpoint (as ``model_checkpoint``; or, ``which`` a number, the
    checkpoint of that iteration of its newest training, as DeepRacer for Cloud's
    ``dr-upload-model -c N`` takes one) when it holds trained weights (``checkpoint_trained``);
    None when the model has none."""
    if which.isdigit():
        job = _newest_trained_job(model)
        name = artifacts.path(model, artifacts.checkpoint(int(which)))
        if job is None or not 0 < int(which) <= job.iterations or not default_storage.exists(name):
            return None
        return name
    name = model_checkpoint(model=model, which=which)
    return name if name and checkpoint_trained(model=model, name=name) else None


def model_untrained(*, model: RLModel, last_checkpoint: str | None = None) -> bool:
    """Whether a READY model has no trained checkpoint: stopped before its first policy update,
    it would drive with the weights training started from. ``last_checkpoint``: its newest
    training's, when the caller has it (a list's prefetched jobs), else looked up."""
    if model.status != RLModel.Status.READY:
        return False
    if last_checkpoint is None:
        last_checkpoint = model_checkpoint(model=model, which="last") or ""
    return not (last_checkpoint and checkpoint_trained(model=model, name=last_checkpoint))


def untrained_refusal(*, model: RLModel, doing: str) -> str:
    """Why a model with no trained checkpoint cannot be raced or downloaded (``doing``: "race",
    "download"), in a racer's words."""
    return (
        f"{model.name} is {UNTRAINED}: its weights are the random ones training starts from, so "
        f"there is nothing to {doing} yet. You may still evaluate it; to {doing} a model, train "
        "one past its first policy update."
    )


def model_status_display(*, model: RLModel, untrained: bool | None = None) -> str:
    """The model's status in the racer's words: "Ready: not trained yet (...)" for a ready
    model with no trained checkpoint (``untrained``, when the caller knows it)."""
    if untrained is None:
        untrained = model_untrained(model=model)
    text = model.get_status_display()
    return f"{text}: {UNTRAINED}" if untrained else text


@dataclass(frozen=True)
class CheckpointChoice:
    """The model's best or last checkpoint, as the Evaluate form and the downloads name it."""

    which: str  # "best" or "last"
    iteration: int | None  # None: weights that came with an import
    evaluation_completion: float | None  # [%] in that iteration's evaluation episodes
    trained: bool = True  # ``checkpoint_trained``
    metric: str = BestCheckpointBy.PROGRESS  # the model's: how its training picks the best
    evaluation_reward: float | None = None  # mean total reward of those episodes
    evaluation_lap_ms: float | None = None  # [ms] their mean lap time, 999999 when unfinished

    @property
    def label(self) -> str:
        if self.iteration is None:
            return EvaluationJob.Checkpoint(self.which).label
        name = "Best" if self.which == EvaluationJob.Checkpoint.BEST else "Last"
        if name == "Best" and self.metric != BestCheckpointBy.PROGRESS:
            name += f" by {BestCheckpointBy(self.metric).label.lower()}"
        if self.iteration == 0:
            started = f"{name}: the weights training started from"
            return started if self.trained else f"{started}, {UNTRAINED}"
        return f"{name}: iteration {self.iteration}{self._figure()}"

    def _figure(self) -> str:
        """The evaluation figure that made the best the best (the model's metric), or the last's
        completion."""
        by = self.metric if self.which == EvaluationJob.Checkpoint.BEST else None
        if by == BestCheckpointBy.REWARD and self.evaluation_reward is not None:
            return f", {self.evaluation_reward:.1f} mean evaluation reward"
        if by == BestCheckpointBy.LAPTIME and self.evaluation_lap_ms is not None:
            return f", {self.evaluation_lap_ms / 1000:.3f} s mean evaluation lap time"
        if self.evaluation_completion is None:
            return ""
        return f", {self.evaluation_completion:.0f}% evaluation completion"


def model_checkpoint_choices(*, model: RLModel) -> list[CheckpointChoice]:
    """The best and the last checkpoint of the model, with the iteration each holds and how
    that iteration did in evaluation; [] when the model has no weights yet."""
    job = _newest_trained_job(model)
    if job is None:
        return []
    names = {which: _checkpoint_of(job, which) for which in EvaluationJob.Checkpoint.values}
    iterations = {which: artifacts.checkpoint_iteration(name) for which, name in names.items()}
    figures = {
        row.pop("number"): row
        for row in Iteration.objects.filter(job=job, number__in=iterations.values()).values(
            "number", "evaluation_completion", "evaluation_reward", "evaluation_lap_ms"
        )
    }
    return [
        CheckpointChoice(
            which,
            number,
            trained=checkpoint_trained(model=model, name=names[which]),
            metric=model.best_checkpoint_by,
            **figures.get(number, {"evaluation_completion": None}),
        )
        for which, number in iterations.items()
    ]


def trial_row(*, trial: EvaluationTrial, line: tuple[float, float] | None = None) -> dict:
    """One trial of an evaluation, for its results table (a ``trial`` message); with ``line``,
    the racing line's laps (``track_lines.line_times``), its lap against the line's: the time
    driven, penalties aside, against a lap from a standing start, as a trial starts (a flying
    one for the laps after the first of continuous laps)."""
    against = ""
    if line is not None and trial.completed:
        flying = trial.evaluation.continuous_laps and trial.number > 1
        driven = (trial.time_ms - trial.penalty_ms) / 1000
        against = track_lines.lap_against_line(driven, line[1] if flying else line[0])
    return {
        "against_line": against,
        "type": "trial",
        "number": trial.number,
        "time_ms": trial.time_ms,
        "progress": trial.progress,
        "status": trial.status,
        "status_display": trial.status_display,
        "off_tracks": trial.off_tracks,
        "crashes": trial.crashes,
        "resets": trial.resets,
        "penalty_ms": trial.penalty_ms,
    }


def evaluation_status(*, evaluation: EvaluationJob) -> dict:
    return {
        "type": "status",
        "status": evaluation.status,
        "status_display": evaluation.get_status_display(),
        "active": evaluation.is_active,
        "message": evaluation.message,
        "failure_reason": evaluation.failure_reason,
        "trials": evaluation.trials,
        "has_video": bool(evaluation.video),
        "workers": 1,
    }


def evaluation_line(*, evaluation: EvaluationJob) -> tuple[float, float] | None:
    """The laps of the racing line of the track ``evaluation`` drives, its way
    (``track_lines.line_times``): what its trials are set against."""
    return track_lines.line_times(track=evaluation.track, direction=evaluation.direction)


def evaluation_trials(*, evaluation: EvaluationJob, line: tuple[float, float] | None) -> list[dict]:
    """Its trials' rows (``trial_row``), each against ``line`` (``evaluation_line``)."""
    return [trial_row(trial=trial, line=line) for trial in evaluation.trial_rows.all()]


def evaluation_snapshot(*, evaluation: EvaluationJob) -> dict:
    return {
        **evaluation_status(evaluation=evaluation),
        "type": "state",
        "history": evaluation_trials(
            evaluation=evaluation, line=evaluation_line(evaluation=evaluation)
        ),
    }


def evaluations_for_model(*, model: RLModel) -> QuerySet[EvaluationJob]:
    """The evaluations the racer ran, and the races their model drove as another racer's rival
    (each labelled with that entry: ``rival_entry``); a race submission's own evaluation is
    listed with the model's races (``races_for_model``) instead."""
    return (
        model.evaluations.filter(submission__isnull=True)
        .select_related("track", "grid_leader__submission__event")
        .select_related("grid_leader__submission__racer__profile")
        .prefetch_related("trial_rows")
    )


def races_for_model(*, model: RLModel) -> QuerySet:
    """The model's race submissions, newest first (the league's ``Submission`` rows, reached
    through their relation so this app need not import the league)."""
    return model.submissions.select_related("event", "event__track").order_by("-created_at")


@dataclass(frozen=True)
class Allowance:
    """What a racer's quota leaves them: models, and training minutes this calendar month (a
    running or queued job counts with its whole time budget, a stopped one with the time it
    used up to the stop)."""

    max_models: int
    models: int
    max_minutes: int
    minutes: float

    @property
    def models_left(self) -> int:
        return max(self.max_models - self.models, 0)

    @property
    def minutes_left(self) -> int:
        return max(int(self.max_minutes - self.minutes), 0)


def allowance_for(*, racer: AbstractBaseUser) -> Allowance:
    quota = Quota.of(racer)
    month = timezone.localtime().replace(day=1, hour=0, minute=0, second=0, microsecond=0)
    this_month = TrainingJob.objects.filter(model__owner=racer, created_at__gte=month)
    active = TrainingJob.ACTIVE
    # A job the racer stopped is billed the time up to the stop (its clock froze there), even
    # while it still saves; one that trains holds its whole budget.
    training = this_month.filter(status__in=active, stop_requested=False)
    # not imports' time
    ran_here = this_month.exclude(pk__in=training).exclude(lease_owner=IMPORTED)
    billed = Least("training_seconds", F("model__max_minutes") * 60.0, output_field=FloatField())
    used = ran_here.aggregate(seconds=Sum(billed))["seconds"]
    reserved = training.aggregate(minutes=Sum("model__max_minutes"))
    return Allowance(
        max_models=quota.max_models,
        models=RLModel.objects.filter(owner=racer).exclude(status=RLModel.Status.DELETING).count(),
        max_minutes=quota.max_minutes_per_month,
        minutes=(used or 0.0) / 60 + (reserved["minutes"] or 0),
    )


def reward_functions_for_racer(*, racer: AbstractBaseUser) -> QuerySet[RewardFunction]:
    """The racer's library of named reward functions, by name."""
    return RewardFunction.objects.filter(owner=racer).order_by(Lower("name"))


@dataclass
class RaceCar:
    """A car of a race of several (model against model), as its evaluations' pages list it."""

    evaluation: int
    place: int  # on the grid, 1 in front
    racer: str
    model_name: str
    status: str
    laps: int  # completed
    time_ms: int  # of the completed laps, penalties included
    crashes: int
    off_tracks: int


def race_cars(*, evaluation: EvaluationJob | None) -> list[RaceCar]:
    """The cars of the race ``evaluation`` drove in (model against model), in grid order, each
    with its own laps and counts; [] when it drove alone (or None: gone with its model)."""
    if evaluation is None:
        return []
    first = evaluation.grid_leader_id or evaluation.pk
    cars = (
        EvaluationJob.objects.filter(Q(pk=first) | Q(grid_leader=first))
        .select_related("model__owner__profile")
        .prefetch_related("trial_rows")
        .order_by("grid_position", "pk")
    )
    if len(cars) < 2:
        return []
    listed = []
    for car in cars:
        trials = list(car.trial_rows.all())
        done = [trial for trial in trials if trial.completed]
        listed.append(
            RaceCar(
                evaluation=car.pk,
                place=car.grid_position + 1,
                racer=racer_name(racer=car.model.owner),
                model_name=car.model.name,
                status=car.get_status_display(),
                laps=len(done),
                time_ms=sum(trial.time_ms for trial in done),
                crashes=sum(trial.crashes for trial in trials),
                off_tracks=sum(trial.off_tracks for trial in trials),
            )
        )
    return listed
