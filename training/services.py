"""Writes for the training app.

Long because the app's writes are kept in one module, as HackSoft's styleguide keeps an app's
services: tracks, vehicles, models, clones, deletes, evaluations and reward functions.
"""

from __future__ import annotations

import functools
import logging
import os
import re
import secrets

from django.conf import settings as django_settings
from django.contrib.auth.models import AbstractBaseUser
from django.core.files.storage import FileSystemStorage, default_storage
from django.db import IntegrityError, transaction
from django.utils import timezone

from common import queueing
from common.refusals import Refused
from common.transactions import SlowStepInTransaction, outside_transaction
from simulator import tracks as simulator_tracks
from training import (
    artifacts,
    configuration,
    leases,
    lifecycle,
    rewards,
    selectors,
    streams,
    track_lines,
)
from training.models import (
    SEEDS,
    Direction,
    EvaluationJob,
    Quota,
    RewardFunction,
    RLModel,
    Track,
    TrainingJob,
    Vehicle,
)

logger = logging.getLogger(__name__)

# The tasks training's services queue, by name (common.queueing): jobs.tasks defines them
TRAIN = "training.train"
EVALUATE = "training.evaluate"


@transaction.atomic
def tracks_sync() -> list[Track]:
    """Mirror the simulator's built-in tracks into the database: add new ones, update the rest.

    A track that has left the catalogue stays (models may still refer to it). Runs at every
    ``make run`` and in most tests, so it reads the rows once and writes only what differs, in
    two statements at most: 16 ms to add the 78 to an empty test database, 9 ms when they are
    already in step (measured on the 2-core machine, SQLite).
    """
    added = set(Track.objects.filter(added_at__isnull=False).values_list("name", flat=True))
    wanted = {name: values for name, values in _catalogue_rows() if name not in added}
    rows = {row.name: row for row in Track.objects.filter(name__in=wanted)}
    new, changed = [], []
    for name, values in wanted.items():
        row = rows.get(name)
        if row is None:
            rows[name] = row = Track(name=name, **values)
            new.append(row)
        elif any(getattr(row, field) != value for field, value in values.items()):
            for field, value in values.items():
                setattr(row, field, value)
            changed.append(row)
    Track.objects.bulk_create(new)
    Track.objects.bulk_update(changed, list(CATALOGUE_FIELDS))
    return [rows[name] for name in wanted]


CATALOGUE_FIELDS = (
    "display_name",
    "description",
    "difficulty",
    "length_m",
    "width_m",
    "counterclockwise",
    "clockwise",
    "default_direction",
    "season",
    "position",
)


@functools.cache
def _catalogue_rows() -> list[tuple[str, dict]]:
    """Each built-in track's row values: DeepRacer's as their catalogue measured them, Pitlane's
    measured here (eight small routes)."""
    found = []
    for position, name in enumerate(simulator_tracks.names()):
        entry = simulator_tracks.entry(name)
        if "length_m" in entry:
            length, width = entry["length_m"], entry["width_m"]
        else:
            track = simulator_tracks.load(name)
            length, width = round(track.length, 2), round(track.width, 3)
        directions = entry["directions"]
        found.append(
            (
                name,
                {
                    "display_name": entry["display_name"],
                    "description": entry["description"],
                    "difficulty": entry["difficulty"],
                    "length_m": length,
                    "width_m": width,
                    "counterclockwise": Direction.COUNTERCLOCKWISE in directions,
                    "clockwise": Direction.CLOCKWISE in directions,
                    "default_direction": directions[0],
                    "season": entry.get("season"),
                    "position": position,
                },
            )
        )
    return found


TRACK_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
ROUTE_MAX_BYTES = 8 * 1024 * 1024  # a DeepRacer route file is a few kilobytes


class TrackRefused(Refused):
    """A track that cannot be added; ``field`` is the input at fault ("route", "name", ...)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__({field: message})
        self.field, self.message = field, message


def track_check(
    *,
    name: str,
    route: bytes,
    directions: list[str] | tuple[str, ...],
    difficulty: str = Track.Difficulty.INTERMEDIATE,
    display_name: str = "",
    description: str = "",
    replace: bool = False,
) -> simulator_tracks.Track:
    """The simulator's track for what ``track_add`` would store, or ``TrackRefused`` saying what is
    wrong. Writes nothing; called outside any transaction, as the route's check is slow work."""
    outside_transaction("A track's route check")
    _track_name_check(name, replace=replace)
    if len(display_name) > Track._meta.get_field("display_name").max_length:
        raise TrackRefused("display_name", "A display name is at most 100 characters.")
    if len(description) > (most := Track._meta.get_field("description").max_length):
        raise TrackRefused("description", f"A description is at most {most} characters.")
    if difficulty not in Track.Difficulty.values:
        raise TrackRefused(
            "difficulty",
            (f"The difficulty is one of {', '.join(Track.Difficulty.values)}, not {difficulty!r}."),
        )
    known = [direction.value for direction in Direction]
    if not directions or any(direction not in known for direction in directions):
        raise TrackRefused(
            "directions", (f"Choose the directions the track is driven: {' and/or '.join(known)}.")
        )
    if not route:
        raise TrackRefused("route", "Choose the track's route file (.npy).")
    if len(route) > ROUTE_MAX_BYTES:
        raise TrackRefused(
            "route",
            (
                f"That file is {len(route) / 1024 / 1024:.1f} MB; a route file is at most "
                f"{ROUTE_MAX_BYTES // 1024 // 1024} MB."
            ),
        )
    try:
        return simulator_tracks.load(
            {
                "name": name,
                "display_name": display_name or name,
                "route": route,
                "directions": list(directions),
                "description": description,
                "difficulty": difficulty,
            }
        )
    except simulator_tracks.TrackError as error:
        raise TrackRefused("route", str(error)) from None


def _track_name_check(name: str, *, replace: bool) -> None:
    """``TrackRefused`` unless ``name`` may name a new track (or, with ``replace``, an added
    track it replaces)."""
    if not TRACK_NAME.fullmatch(name or ""):
        raise TrackRefused(
            "name",
            (
                "A track name is 1 to 64 letters, digits, '_' or '-', starting with a letter or "
                "digit, like my_track_2."
            ),
        )
    if name in simulator_tracks.names():
        raise TrackRefused("name", f"{name} is a built-in track; choose another name.")
    if (builtin := simulator_tracks.world(name)) is not None:  # load(name) would find it first
        shown = simulator_tracks.entry(builtin[0])["display_name"]
        raise TrackRefused(
            "name",
            (
                f"{name} is DeepRacer's name for the built-in {shown} ({builtin[1]}); choose "
                "another name."
            ),
        )
    existing = Track.objects.filter(name=name).first()
    if existing is not None and (existing.builtin or not replace):
        raise TrackRefused(
            "name",
            (
                f"There is already a track named {name} ({existing.display_name})"
                + ("." if existing.builtin else "; replace it, or choose another name.")
            ),
        )


def track_add(
    *,
    name: str,
    display_name: str,
    route: bytes,
    directions: list[str] | tuple[str, ...],
    description: str = "",
    difficulty: str = Track.Difficulty.INTERMEDIATE,
    added_by: AbstractBaseUser | None = None,
    replace: bool = False,
) -> Track:
    """Add a track from a DeepRacer route file (``route``: the ``.npy`` file's bytes) so racers can
    train, evaluate and race on it; with ``replace``, update the added track of that name instead.

    The route is checked by the simulator's loader; the row keeps the file, its length and width
    and a preview. ``TrackRefused`` says what is wrong. The check and the preview are done before
    the transaction that writes the row, so no other writer waits behind them.
    """
    display_name = display_name or name
    track = track_check(
        name=name,
        route=route,
        directions=directions,
        difficulty=difficulty,
        display_name=display_name,
        description=description,
        replace=replace,
    )
    # The preview shows the track as first offered, with its arrow in that direction.
    shown = track.with_direction(next(iter(directions)))
    # Drawn with OpenCV, which only adding a track needs: imported here, not when the web starts.
    from simulator import texture

    try:
        png = texture.preview_png(shown)
    except ValueError as error:
        raise TrackRefused("route", "The track's preview could not be drawn.") from error
    with transaction.atomic():
        row = _track_row_save(
            name=name,
            display_name=display_name,
            route=route,
            directions=directions,
            description=description,
            difficulty=difficulty,
            added_by=added_by,
            track=track,
            png=png,
            replace=replace,
        )
        # A worker computes its lines once committed.
        track_lines.track_lines_request_all(track=row, geometry=track)
    return row


def _track_row_save(
    *, name, display_name, route, directions, description, difficulty, added_by, track, png, replace
) -> Track:
    existing = Track.objects.select_for_update().filter(name=name).first()
    if existing is not None and (existing.builtin or not replace):  # added since it was checked
        raise TrackRefused("name", f"There is already a track named {name}; choose another name.")
    row = existing or Track(name=name)
    if existing is None:
        last = Track.objects.order_by("-position").values_list("position", flat=True).first()
        row.position = min((last or 0) + 1, 32_767)
    row.display_name, row.description, row.difficulty = display_name, description, difficulty
    row.length_m, row.width_m = round(track.length, 2), round(track.width, 3)
    row.counterclockwise = Direction.COUNTERCLOCKWISE in directions
    row.clockwise = Direction.CLOCKWISE in directions
    row.route, row.preview = bytes(route), png
    if added_by is not None or existing is None:
        row.added_by = added_by
    row.added_at = timezone.now()
    row.save()
    return row


def vehicle_create(
    *, owner: AbstractBaseUser, name: str, shell_colour: str, camera: str, lidar: str
) -> Vehicle:
    vehicle = Vehicle(owner=owner, name=name, shell_colour=shell_colour, camera=camera, lidar=lidar)
    vehicle.full_clean()
    vehicle.save()
    return vehicle


class VehicleSensorsLocked(Refused):
    """The vehicle's sensors cannot change: models were trained on them."""


def vehicle_update(
    *, vehicle: Vehicle, name: str, shell_colour: str, camera: str, lidar: str
) -> Vehicle:
    """Rename or repaint the vehicle. Its sensors change only while no model was trained on it:
    a model's network reads exactly the sensors it was trained with. Models already trained keep
    the colour they were created in."""
    if (camera, lidar) != (vehicle.camera, vehicle.lidar) and vehicle.rl_models.exists():
        raise VehicleSensorsLocked(
            f"Models were trained on {vehicle.name}'s sensors, so they cannot change; "
            "build a new vehicle to try other sensors."
        )
    vehicle.name, vehicle.shell_colour = name, shell_colour
    vehicle.camera, vehicle.lidar = camera, lidar
    vehicle.full_clean()
    vehicle.save()
    return vehicle


def vehicle_delete(*, vehicle: Vehicle) -> None:
    """Remove the vehicle from the garage. Models trained on it keep their sensors and colour
    (their link to it is cleared)."""
    vehicle.delete()


def check_quota(*, owner: AbstractBaseUser, minutes: int) -> None:
    """Within a transaction: ``configuration.Invalid`` unless the racer may have one more model
    that trains for up to ``minutes``. Their quota row is locked until the transaction ends, so
    two models created at once cannot both take the last of it."""
    Quota.objects.select_for_update().filter(pk=Quota.of(owner).pk).first()
    allowance = selectors.allowance_for(racer=owner)
    if allowance.models_left < 1:
        raise configuration.Invalid(
            {"quota": (f"You have {allowance.models} models, your limit; delete one to make room.")}
        )
    if minutes > allowance.minutes_left:
        raise configuration.Invalid(
            {
                "max_minutes": (
                    f"You have {allowance.minutes_left} training minutes left this month (of "
                    f"{allowance.max_minutes}); choose at most that, or wait for the 1st."
                )
            }
        )


def model_create(
    *,
    owner: AbstractBaseUser,
    settings: configuration.Draft,
    validate_reward: bool = True,
    validation: rewards.Validation | None = None,
) -> RLModel:
    """Check every setting (``configuration.Invalid`` lists the problems), then save the model and
    its training job, QUEUED; the trainer task is enqueued once both are committed. A clone
    (``cloned_from``: the racer's own READY model) gets a copy of its source's best weights, which
    its training starts from: copied after the rows are committed, before its trainer is sent
    (``clone_weights_copy``). ``validation``: the reward function's, already found by a checker
    (see ``configuration.check``); without it, the reward function is validated here, in the
    sandbox, before the transaction that saves opens, so no other writer waits on it (SQLite
    takes its write lock when the transaction begins); the copy waits for no transaction either."""
    if validation is None and validate_reward:
        validation = _reward_validation(settings)
    with transaction.atomic():
        model, job, weights = _model_save(owner, settings, validate_reward, validation)
    if weights is not None and not _clone_weights_start(job, weights):
        return model
    # A send that fails (the broker unreachable) is logged, not the racer's error: the
    # workers send a queued task that is not in the broker again (console.recovery).
    transaction.on_commit(lambda: queueing.enqueue(TRAIN, job.pk), robust=True)
    return model


CLONE_COPY_FAILED = (
    "The weights of the model it was cloned from could not be copied ({why}), so it did not "
    "start training; delete it and clone that model again."
)


def clone_weights_copy(*, model: RLModel, weights: str | None = None) -> str | None:
    """Copy the clone ``model``'s starting weights, its source's chosen trained checkpoint
    (``weights``, when the caller has looked it up), to where its training starts from
    (``artifacts.CLONED_WEIGHTS``); None once copied, else why not, in the racer's words, for
    ``CLONE_COPY_FAILED``. File work (a checkpoint may be hundreds of MiB), so never inside a
    transaction; the copy appears there whole or not at all (``_save_whole``), so a trainer
    never starts from part of it. ``model_create`` copies them; a trainer that finds no copy
    (its request died before it made one) makes it."""
    if weights is None:
        source = RLModel.objects.filter(pk=model.cloned_from_id).first()
        which = model.cloned_checkpoint or "best"
        weights = selectors.model_trained_checkpoint(model=source, which=which) if source else None
    if weights is None:
        return "that model was deleted"
    try:
        _save_whole(model, artifacts.CLONED_WEIGHTS, artifacts.read(weights))
    except SlowStepInTransaction:
        raise
    except Exception:
        logger.exception("The clone %s's starting weights could not be copied", model.pk)
        return "storage failed"
    return None


def _save_whole(model: RLModel, relative: str, data: bytes) -> None:
    """Save ``data`` at ``relative`` under the model's prefix so that a reader finds all of it
    or nothing: on local storage under a temporary name of its own (another writer's is left
    alone), then renamed (a rename is atomic); a bucket's object appears only once all of it is
    uploaded."""
    if not isinstance(default_storage, FileSystemStorage):
        artifacts.save(model, relative, data)
        return
    partial = artifacts.save(model, f"{relative}.{secrets.token_hex(8)}.partial", data)
    os.replace(default_storage.path(partial), default_storage.path(artifacts.path(model, relative)))


def _clone_weights_start(job: TrainingJob, weights: str) -> bool:
    """Copy a new clone's starting weights (its source's checkpoint ``weights``); whether its
    trainer may be sent. Its send stays held meanwhile (``leases.lease_renewed``), so the
    workers' ``recovery.resend_lost`` does not send its trainer before they are all there,
    however long the copy takes; a request that dies copying lets the hold lapse, and a trainer
    sent then copies them. Where they cannot be copied, its job fails in words and the model is
    ERROR, for the racer to delete."""
    with leases.lease_renewed(job):
        why = clone_weights_copy(model=job.model, weights=weights)
    if why is None:
        return True
    with transaction.atomic():
        locked = TrainingJob.objects.select_for_update().get(pk=job.pk)
        if locked.status != TrainingJob.Status.QUEUED or locked.attempt:
            return False  # stopped by the racer meanwhile, or taken by a trainer, which copies
        lifecycle.TRAINING_JOB.move(locked, TrainingJob.Status.STOPPING)
        lifecycle.TRAINING_JOB.move(
            locked,
            TrainingJob.Status.FAILED,
            finished_at=timezone.now(),
            lease_expires=None,
            failure_reason=CLONE_COPY_FAILED.format(why=why),
        )
        lifecycle.MODEL.move(job.model_id, RLModel.Status.ERROR)
    streams.announce_training(job.pk)
    streams.announce_queue()
    return False


def model_insert(
    *, owner: AbstractBaseUser, settings: configuration.ModelSettings, status: str
) -> RLModel:
    """Within a transaction: the model's row, with ``settings`` (checked) and ``status``.
    ``configuration.Invalid`` on its name where another request of the racer's took that name
    since ``configuration.check`` found it free (two confirms of one import at once): the
    database's constraint decides, in a savepoint, so the caller's transaction goes on."""
    try:
        with transaction.atomic():
            return RLModel.objects.create(owner=owner, status=status, **settings.row())
    except IntegrityError:
        problem = configuration.name_problem(settings.name, owner=owner)
        if problem is None:
            raise
        raise configuration.Invalid({"name": problem}) from None


def _reward_validation(settings: configuration.Draft) -> rewards.Validation | None:
    """The validation ``configuration.check`` would run for ``settings``; None where it runs
    none (no reward function, or no track to validate it on)."""
    source = settings.get("reward_function") or ""
    where = configuration.reward_sample_track(settings) if source.strip() else None
    if where is None:
        return None
    return rewards.reward_validate(source=source, track=where[0], direction=where[1])


def _model_save(
    owner: AbstractBaseUser,
    draft: configuration.Draft,
    validate_reward: bool,
    validation: rewards.Validation | None,
) -> tuple[RLModel, TrainingJob, str | None]:
    """The model's and its job's rows, and a clone's source's checkpoint, to be copied."""
    settings = configuration.check(
        draft, owner=owner, validate_reward=validate_reward, validation=validation
    )
    check_quota(owner=owner, minutes=settings.max_minutes)
    source = settings.cloned_from
    if source is not None and source.owner_id != owner.pk:
        raise configuration.Invalid({"cloned_from": "You can clone only your own models."})
    weights = (
        selectors.model_trained_checkpoint(model=source, which=settings.cloned_checkpoint)
        if source is not None
        else None
    )
    if source is not None and weights is None and settings.cloned_checkpoint.isdigit():
        raise configuration.Invalid(
            {
                "cloned_checkpoint": (
                    f"{source.name} has no checkpoint of iteration {settings.cloned_checkpoint}: "
                    "choose one of the iterations its latest training ran, or best or last."
                )
            }
        )
    if source is not None and weights is None:
        raise configuration.Invalid(
            {
                "cloned_from": (
                    f"{source.name} is {selectors.UNTRAINED}: it has no trained weights to clone."
                )
            }
        )
    if source is not None:  # its weights are for its source's network
        settings = settings.replace(network_layout=source.network_layout)
    model = model_insert(owner=owner, settings=settings, status=RLModel.Status.QUEUED)
    if source is None:
        return model, TrainingJob.objects.create(model=model), None
    # Its weights are copied once this commits: its send is held meanwhile, so
    # console.recovery.resend_lost does not send its trainer before they are there
    # (_clone_weights_start).
    held = {"lease_owner": leases.RESUMING, "lease_expires": timezone.now() + leases.lease()}
    return model, TrainingJob.objects.create(model=model, **held), weights


def training_stop(*, job: TrainingJob) -> TrainingJob:
    """The racer's "Stop training": a running job moves through STOPPING to COMPLETED with the
    model of its last finished iteration (the trainer abandons one it is learning, within seconds);
    its clock stops now, and the time up to now is what it is billed. A job still waiting in the
    queue is canceled."""
    with transaction.atomic():
        job = TrainingJob.objects.select_for_update().get(pk=job.pk)
        if job.status == TrainingJob.Status.QUEUED and job.attempt == 0:
            lifecycle.TRAINING_JOB.move(
                job,
                TrainingJob.Status.CANCELED,
                finished_at=timezone.now(),
                failure_reason="Stopped before training began.",
            )
            lifecycle.MODEL.move(job.model_id, RLModel.Status.ERROR)
        elif job.is_active and not job.stop_requested:
            clock = selectors.training_clock(job=job)  # frozen here: the time billed
            lifecycle.TRAINING_JOB.move(
                job,
                TrainingJob.Status.STOPPING,
                stop_requested=True,
                message=leases.saving_message(job.iterations),
                training_seconds=clock.seconds,
                clock_at=clock.at,
            )
            lifecycle.MODEL.move(job.model_id, RLModel.Status.STOPPING)
    streams.announce_training(job.pk)
    if job.status == TrainingJob.Status.CANCELED:
        streams.announce_queue()
    return job


class ModelBusy(Refused):
    """The model is training, evaluating or racing; the message says what to wait for."""


def model_delete(*, model: RLModel) -> int:
    """Delete a READY or ERROR model: its rows, and every object stored under its prefix (how
    many is returned). The model is DELETING meanwhile, so nothing starts on it."""
    with transaction.atomic():
        locked = RLModel.objects.select_for_update().get(pk=model.pk)
        was = locked.status
        deletable = frozenset(RLModel.DELETABLE)
        if not lifecycle.MODEL.move(locked, RLModel.Status.DELETING, only_from=deletable):
            raise ModelBusy(
                f"The model is {locked.get_status_display().lower()}; it can be deleted once it "
                "is ready (stop its training first) or has failed."
            )
        racing = EvaluationJob.objects.filter(model=locked, status__in=EvaluationJob.ACTIVE)
        if racing.exists():  # another racer's race, against this one (the move rolls back)
            raise ModelBusy(
                f"{locked.name} is racing against another racer's model in their race; delete "
                "it once that race ends (a few minutes)."
            )
        waiting = _clone_waiting(locked)
        if waiting is not None:  # (the move to DELETING rolls back)
            raise ModelBusy(
                f"{waiting}, cloned from it, has not started training from its weights yet; "
                f"delete this model once {waiting} trains, or stop {waiting} first."
            )
    try:
        removed = artifacts.delete_all(model)
    except Exception:
        # Storage failed part-way: the model stays, as it was, for the racer to delete again.
        lifecycle.MODEL.move(model.pk, was)
        raise
    model.delete()
    return removed


def _clone_waiting(source: RLModel) -> str | None:
    """The name of a clone of ``source`` that has not yet started from its weights (its job
    waits, with no checkpoint of its own), if any: once ``source`` is deleted, a clone no
    longer says it is one (``cloned_from`` is cleared), and its trainer could neither find its
    copy of them nor make one."""
    waiting = TrainingJob.objects.filter(
        model__cloned_from=source,
        last_checkpoint="",
        status__in=(TrainingJob.Status.QUEUED, TrainingJob.Status.INITIALIZING),
    )
    return waiting.values_list("model__name", flat=True).first()


class EvaluationRefused(Refused):
    """The model cannot be evaluated now; the message says why."""


def evaluation_start(
    *, model: RLModel, settings: dict, seed: int | None = None, enqueue: bool = True
) -> EvaluationJob:
    """Check the settings (``configuration.Invalid``), then queue an evaluation of a ready model
    and mark the model EVALUATING; the task is enqueued once committed (unless ``enqueue`` is
    False: ``manage.py evaluate`` runs it in its own process). ``seed``: an earlier
    evaluation's or race's, to drive its trials again with the same settings; None, a new one."""
    clean = configuration.check_evaluation(settings, model=model)
    if seed is not None:
        if not 0 <= seed < SEEDS:
            raise configuration.Invalid({"seed": configuration.SEED_RANGE})
        clean["seed"] = seed
    with transaction.atomic():
        evaluation = evaluation_reserve(model=model, purpose=RLModel.Status.EVALUATING, **clean)
        if enqueue:
            # A failed send is logged, not the racer's error: the workers send
            # a queued task that is not in the broker again (console.recovery).
            transaction.on_commit(lambda: queueing.enqueue(EVALUATE, evaluation.pk), robust=True)
    return evaluation


def evaluation_reserve(*, model: RLModel, purpose: str, **fields) -> EvaluationJob:
    """Within a transaction: a QUEUED evaluation of ``model`` with checked ``fields``, the model
    marked ``purpose`` (EVALUATING, or SUBMITTING for a race) under a row lock, so that one model
    drives one evaluation at a time. ``EvaluationRefused`` unless it is ready and has weights."""
    model = RLModel.objects.select_for_update().get(pk=model.pk)
    waiting = EvaluationJob.objects.filter(
        model__owner_id=model.owner_id, status__in=EvaluationJob.ACTIVE
    ).count()
    if waiting >= django_settings.PITLANE_MAX_QUEUED_EVALUATIONS:
        raise EvaluationRefused(
            f"You have {waiting} evaluations and race entries waiting or driving, the most at "
            "once here; start another when one has finished."
        )
    if model.status != RLModel.Status.READY:
        raise EvaluationRefused(
            f"The model {model.name} is {model.get_status_display().lower()}; "
            "it can be evaluated or raced once it is ready."
        )
    if selectors.model_checkpoint(model=model) is None:
        raise EvaluationRefused(
            f"The model {model.name} has no trained weights yet; train it first."
        )
    if purpose == RLModel.Status.SUBMITTING and selectors.model_untrained(model=model):
        raise EvaluationRefused(selectors.untrained_refusal(model=model, doing="race"))
    evaluation = EvaluationJob.objects.create(model=model, **fields)
    lifecycle.MODEL.move(model, purpose, only_from=frozenset({RLModel.Status.READY}))
    return evaluation


def evaluation_rival_add(
    *, leader: EvaluationJob, model: RLModel, position: int, **fields
) -> EvaluationJob:
    """Within the transaction that made ``leader`` (a race's first car): another racer's
    ``model`` raced against it at grid ``position`` under the same ``fields`` (race rules). The
    model is not reserved: it may train or race meanwhile, as the leaderboard's models do; its
    weights are read when the race starts, and it cannot be deleted until the race ends."""
    return EvaluationJob.objects.create(
        model=model, grid_leader=leader, grid_position=position, rival=True, **fields
    )


def evaluation_stop(*, evaluation: EvaluationJob) -> EvaluationJob:
    """The racer's "Stop evaluation" (DeepRacer's console had it): one still waiting is canceled
    at once and its model is ready again; a running one is asked to stop (STOPPING), and its run
    notices within a second, ends it CANCELED with the trials it finished (their video and trace
    kept) and frees the model. A race entry's evaluation runs to its end (``EvaluationRefused``);
    one that has ended is returned as it is."""
    if EvaluationJob.objects.filter(pk=evaluation.pk, submission__isnull=False).exists():
        raise EvaluationRefused("A race entry drives to its end; it cannot be stopped.")
    if EvaluationJob.objects.filter(pk=evaluation.pk, rival=True).exists():
        raise EvaluationRefused(
            "Your model is racing against another racer's in their race: it drives to its end."
        )
    statuses = EvaluationJob.Status
    with transaction.atomic():
        evaluation = EvaluationJob.objects.select_for_update().get(pk=evaluation.pk)
        if evaluation.status == statuses.QUEUED:
            lifecycle.EVALUATION.move(
                evaluation,
                statuses.CANCELED,
                finished_at=timezone.now(),
                message="",
                failure_reason="Stopped by you before it began.",
            )
            lifecycle.MODEL.move(
                evaluation.model_id,
                RLModel.Status.READY,
                only_from=frozenset({RLModel.Status.EVALUATING}),
            )
        elif evaluation.status in (statuses.INITIALIZING, statuses.IN_PROGRESS):
            lifecycle.EVALUATION.move(
                evaluation,
                statuses.STOPPING,
                message="Stopping: the trials it finished are kept",
            )
    streams.announce(
        streams.evaluation_group(evaluation.pk), selectors.evaluation_status(evaluation=evaluation)
    )
    return evaluation


class RewardFunctionInvalid(Refused):
    """The reward function was not saved: ``errors`` says why, by field (``name``, ``source``);
    ``validation`` holds the code's problems, line by line, when the code was run."""

    def __init__(self, errors: dict[str, str], validation: rewards.Validation | None = None):
        super().__init__(errors)
        self.validation = validation


def reward_function_save(
    *,
    owner: AbstractBaseUser,
    name: str,
    source: str,
    track: str,
    reward_function: RewardFunction | None = None,
    validation: rewards.Validation | None = None,
) -> RewardFunction:
    """Save the racer's code under ``name`` in their library: a new function, or their
    ``reward_function`` changed (renamed too). The code is validated first, on ``track``'s
    samples, unless ``validation`` is that of a checker (``training.checkers``) for the same code;
    names are unique per racer, whatever their case (``RewardFunctionInvalid``)."""
    if reward_function is not None and reward_function.owner_id != owner.pk:
        raise RewardFunctionInvalid({"name": "You can change only your own reward functions."})
    name = " ".join(name.split())
    source = reward_source(source)
    errors = {}
    max_length = RewardFunction._meta.get_field("name").max_length
    if not name:
        errors["name"] = "Name your reward function to save it."
    elif len(name) > max_length:
        errors["name"] = f"A name is at most {max_length} characters long."
    elif _reward_function_named(owner, name, besides=reward_function):
        errors["name"] = (
            f"You already have a reward function named “{name}”; choose another name, "
            "or open that one from your list to change it."
        )
    if not source.strip():
        validation = None
        errors["source"] = "Write a reward function first."
    else:
        if validation is None:
            validation = rewards.reward_validate(source=source, track=track)
        elif validation.source != source:
            raise ValueError("The validation given is of other code than the one to save.")
        if not validation.valid:
            count = len(validation.errors)
            errors["source"] = (
                f"It was not saved: the code has {count} error{'s' if count > 1 else ''} to fix."
            )
    if errors:
        raise RewardFunctionInvalid(errors, validation)
    function = reward_function or RewardFunction(owner=owner)
    function.name, function.source = name, source
    try:
        with transaction.atomic():
            function.save()
    except IntegrityError:  # the same name saved a moment ago, from another tab
        raise RewardFunctionInvalid(
            {"name": f"You already have a reward function named “{name}”; choose another name."}
        ) from None
    return function


def reward_source(source: str) -> str:
    """The code as it is saved: a form's textarea sends CRLF; the editor has LF."""
    return source.replace("\r\n", "\n")


def _reward_function_named(
    owner: AbstractBaseUser, name: str, *, besides: RewardFunction | None
) -> bool:
    same = RewardFunction.objects.filter(owner=owner, name__iexact=name)
    return same.exclude(pk=besides.pk).exists() if besides else same.exists()


def reward_function_delete(*, reward_function: RewardFunction) -> None:
    """Take a function out of the racer's library; models created with it keep their copy."""
    reward_function.delete()
