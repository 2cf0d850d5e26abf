"""A racer's models in the API: create from DeepRacer's files, list, one with its checkpoints,
its iterations, stop, delete.

The same rules as the model's pages, through the same selectors and services: another racer's
model answers 404, as a missing one does; a model that cannot be stopped or deleted now answers
409 with the page's words.
"""

from __future__ import annotations

from datetime import datetime
from typing import Literal

from asgiref.sync import sync_to_async
from django.db.models import Q
from ninja import Field, Query, Router, Schema, Status

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError, counted, reward_checked
from api.owned import own_model
from api.schemas import REFUSED, named_choices
from archives.deepracer_settings import archive_settings
from archives.members import Members, member_json
from training import configuration, models, selectors, services
from training.models import Iteration, RLModel, TrainingJob

router = Router()
ModelStatus = named_choices(RLModel.Status, "ModelStatus")
TrainingStatus = named_choices(TrainingJob.Status, "TrainingStatus")
Direction = named_choices(models.Direction, "Direction")
RaceType = named_choices(models.RaceType, "RaceType")
BestCheckpointBy = named_choices(models.BestCheckpointBy, "BestCheckpointBy")
PAGE_MAX = 100


class ModelOut(Schema):
    id: int
    name: str
    status: ModelStatus
    track: str
    algorithm: str
    sensors: list[str]
    action_space_type: str
    created_at: datetime


class Checkpoints(Schema):
    best: str | None
    last: str | None
    iterations: int


class ModelDetail(ModelOut):
    description: str
    direction: Direction
    race_type: RaceType
    network: str
    action_space: list | dict
    hyperparameters: dict
    max_minutes: int
    workers: int
    seed: int
    domain_randomisation: bool
    best_checkpoint_by: BestCheckpointBy
    evaluation_trials: int
    cloned_from: int | None
    checkpoints: Checkpoints


class ModelPage(Schema):
    count: int
    items: list[ModelOut]


class ModelFilters(Schema):
    status: ModelStatus | None = None
    track: str | None = None
    q: str | None = None
    limit: int = Field(50, ge=1, le=PAGE_MAX)
    offset: int = Field(0, ge=0, le=10**9)


class IterationOut(Schema):
    number: int
    reward: float
    completion: float
    evaluation_completion: float | None
    best_lap_time: float | None
    episodes: int
    steps: int


class Stopped(Schema):
    status: TrainingStatus
    message: str


class Deleted(Schema):
    files_removed: int


def _model_out(model: RLModel) -> dict:
    return {
        "id": model.pk,
        "name": model.name,
        "status": model.status,
        "track": model.track.name,
        "algorithm": model.algorithm,
        "sensors": model.sensors,
        "action_space_type": model.action_space_type,
        "created_at": model.created_at,
    }


@router.get("", response={200: ModelPage, **REFUSED})
def models_list(request, filters: Query[ModelFilters]):
    """Your models, newest first: ``status`` and ``track`` (its name) narrow them, ``q`` finds
    names and descriptions; ``limit`` (1 to 100) and ``offset`` page them."""
    need(request, TokenScope.READ)
    found = selectors.models_for_racer(racer=request.user).order_by("-created_at", "-pk")
    if filters.status:
        found = found.filter(status=filters.status.value)
    if filters.track:
        found = found.filter(track__name=filters.track)
    if filters.q:
        found = found.filter(Q(name__icontains=filters.q) | Q(description__icontains=filters.q))
    page = found[filters.offset : filters.offset + filters.limit]
    return {"count": found.count(), "items": [_model_out(model) for model in page]}


@router.get("/{model_id}", response={200: ModelDetail, **REFUSED})
def model_detail(request, model_id: int):
    """One of your models, with its settings and the checkpoints of its latest training."""
    need(request, TokenScope.READ)
    model = own_model(request, model_id)
    job = model.latest_job
    return {
        **_model_out(model),
        "description": model.description,
        "direction": model.direction,
        "race_type": model.race_type,
        "network": model.network,
        "action_space": model.action_space,
        "hyperparameters": model.hyperparameters,
        "max_minutes": model.max_minutes,
        "workers": model.workers,
        "seed": model.seed,
        "domain_randomisation": model.domain_randomisation,
        "best_checkpoint_by": model.best_checkpoint_by,
        "evaluation_trials": model.evaluation_trials,
        "cloned_from": model.cloned_from_id,
        "checkpoints": {
            "best": (job.best_checkpoint or None) if job else None,
            "last": (job.last_checkpoint or None) if job else None,
            "iterations": job.iterations if job else 0,
        },
    }


@router.get("/{model_id}/iterations", response={200: list[IterationOut], **REFUSED})
def model_iterations(request, model_id: int):
    """The iterations of the model's latest training, first to last: each one's average reward
    and progress, its evaluation's progress, its best lap, episodes and steps (the training
    graph's points)."""
    need(request, TokenScope.READ)
    job = own_model(request, model_id).latest_job
    if job is None:
        return []
    return list(Iteration.objects.filter(job=job).order_by("number"))


@router.post("/{model_id}/stop", response={200: Stopped, **REFUSED})
def model_stop(request, model_id: int):
    """Stop the model's training, as its page's Stop training does: a job in the queue is
    canceled; a running one saves the model of its last finished iteration, billed up to now."""
    need(request, TokenScope.TRAIN)
    job = own_model(request, model_id).latest_job
    if job is None or not job.is_active:
        raise ApiError(409, "not_training", "This model is not training.")
    job = services.training_stop(job=job)
    return {"status": job.status, "message": job.message or job.failure_reason}


@router.delete("/{model_id}", response={200: Deleted, **REFUSED})
def model_delete(request, model_id: int):
    """Delete the model and every file of it, as its page's Delete does: a model that trains,
    evaluates or races is refused (409) with what to wait for."""
    need(request, TokenScope.TRAIN)
    model = own_model(request, model_id)
    try:
        return {"files_removed": services.model_delete(model=model)}
    except services.ModelBusy as busy:
        raise ApiError(409, "busy", str(busy)) from None


class CreateIn(Schema):
    """A model as DeepRacer for Cloud's folder describes it: its files' texts by name."""

    files: dict[str, str]
    name: str | None = None
    description: str = "Created through the API."
    max_minutes: int | None = None


class Created(ModelDetail):
    notes: list[str]


class CloneIn(Schema):
    """A clone, as the Clone page makes one: its new name, the source's checkpoint it starts
    from, and what it may change (the weights fix the sensors, network, algorithm and number of
    actions)."""

    name: str
    checkpoint: Literal["best", "last"] | int = "best"  # or the number of an iteration
    description: str | None = None
    track: str | None = None
    direction: str | None = None
    reward_function: str | None = None
    hyperparameters: dict | None = None
    action_space: list | dict | None = None
    max_minutes: int | None = None


@router.post("", response={201: Created, **REFUSED})
async def model_create(request, body: CreateIn):
    """Create a model and queue its training from DeepRacer's files, as a DeepRacer for Cloud
    folder holds them: ``model_metadata.json`` (sensors, network, action space, algorithm),
    ``reward_function.py``, and where given ``hyperparameters.json`` and
    ``training_params.yaml`` (the track, race type, workers). What this console reads
    differently or leaves out is listed in ``notes``. The reward function is validated first,
    as the create page does; the racer's quotas and create limit hold."""
    need(request, TokenScope.TRAIN)
    notes: list[str] = []
    draft = await sync_to_async(_draft_from_files)(body, notes)
    return await _created(request, draft, notes)


@router.post("/{model_id}/clone", response={201: Created, **REFUSED})
async def model_clone(request, model_id: int, body: CloneIn):
    """Clone one of your trained models, as its Clone button does: the new model starts training
    from the source's ``best`` or ``last`` checkpoint, or that of the iteration numbered, with the
    source's settings but for those given (its track, reward function, hyperparameters, the
    actions' angles and speeds, time)."""
    need(request, TokenScope.TRAIN)
    draft = await sync_to_async(_clone_draft)(request, model_id, body)
    return await _created(request, draft, [])


def _clone_draft(request, model_id: int, body: CloneIn) -> configuration.Draft:
    source = own_model(request, model_id)
    if not source.trainable:
        raise ApiError(
            409,
            "refused",
            f"{source.name} cannot be cloned: it came from a car archive, with its policy alone "
            "(no reward function, no critics) to train on.",
        )
    changes = body.dict(exclude_none=True, exclude={"checkpoint"})
    return {
        **configuration.ModelSettings.of(source).draft(),
        "description": f"Cloned from {source.name}.",
        **changes,
        "cloned_from": source,
        "cloned_checkpoint": str(body.checkpoint),
    }


async def _created(request, draft: configuration.Draft, notes: list[str]) -> Status:
    """The model ``draft`` describes, made as the create page makes it: the racer's create
    limit, the reward function validated by a checker, the settings checked, training queued."""
    await sync_to_async(counted)(request, "create")
    # The settings first, then the check where they drive (the fuzzed document sent a clone
    # with direction "", which the check passed on to the sandbox's child, which crashed).
    track, direction = await sync_to_async(_checked_where)(request, draft)
    checked = await reward_checked(
        draft["reward_function"], track, racer=request.user.pk, direction=direction
    )
    if not checked.valid:
        first = checked.errors[0]
        where = f" (line {first.line})" if first.line else ""
        raise ApiError(400, "reward_invalid", f"reward_function.py{where}: {first.message}")
    model = await sync_to_async(services.model_create)(
        owner=request.user, settings=draft, validation=checked
    )
    return Status(201, {**await sync_to_async(model_detail)(request, model.pk), "notes": notes})


def _checked_where(request, draft: configuration.Draft) -> tuple[str, str]:
    """Where ``draft``'s reward function is checked (track, direction), once its settings are
    checked (``configuration.Invalid`` for those at fault)."""
    configuration.check(draft, owner=request.user, validate_reward=False)
    return configuration.reward_sample_track(draft)


def _draft_from_files(body: CreateIn, notes: list[str]) -> configuration.Draft:
    members = Members({name: text.encode() for name, text in body.files.items()})
    metadata = member_json(members, "model_metadata.json")
    reward = body.files.get("reward_function.py")
    if metadata is None or reward is None:
        raise ApiError(
            400, "invalid", "files must hold model_metadata.json and reward_function.py."
        )
    draft = archive_settings(metadata, {}, members, reward, body.name or "", notes)
    draft["description"] = body.description
    if body.max_minutes is not None:
        draft["max_minutes"] = body.max_minutes
    return draft
