"""A racer's models in the API: list, one with its checkpoints, its iterations, stop, delete.

The same rules as the model's pages, through the same selectors and services: another racer's
model answers 404, as a missing one does; a model that cannot be stopped or deleted now answers
409 with the page's words.
"""

from __future__ import annotations

from datetime import datetime

from django.db.models import Q
from ninja import Query, Router, Schema

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError
from api.schemas import REFUSED
from training import selectors, services
from training.models import Iteration, RLModel, TrainingJob

router = Router()
PAGE_MAX = 100


class ModelOut(Schema):
    id: int
    name: str
    status: RLModel.Status
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
    network: str
    action_space: list | dict
    hyperparameters: dict
    max_minutes: int
    cloned_from: int | None
    checkpoints: Checkpoints


class ModelPage(Schema):
    count: int
    items: list[ModelOut]


class ModelFilters(Schema):
    status: RLModel.Status | None = None
    track: str | None = None
    q: str | None = None
    limit: int = 50
    offset: int = 0


class IterationOut(Schema):
    number: int
    reward: float
    completion: float
    evaluation_completion: float | None
    best_lap_time: float | None
    episodes: int
    steps: int


class Stopped(Schema):
    status: TrainingJob.Status
    message: str


class Deleted(Schema):
    files_removed: int


def _own(request, model_id: int) -> RLModel:
    model = selectors.models_for_racer(racer=request.user).filter(pk=model_id).first()
    if model is None:
        raise ApiError(404, "not_found", f"No model of yours has the id {model_id}.")
    return model


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
    if not 1 <= filters.limit <= PAGE_MAX or filters.offset < 0:
        raise ApiError(400, "invalid", f"limit is 1 to {PAGE_MAX}, and offset 0 or more.")
    found = selectors.models_for_racer(racer=request.user).order_by("-created_at", "-pk")
    if filters.status:
        found = found.filter(status=filters.status)
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
    model = _own(request, model_id)
    job = model.latest_job
    return {
        **_model_out(model),
        "description": model.description,
        "network": model.network,
        "action_space": model.action_space,
        "hyperparameters": model.hyperparameters,
        "max_minutes": model.max_minutes,
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
    job = _own(request, model_id).latest_job
    if job is None:
        return []
    return list(Iteration.objects.filter(job=job).order_by("number"))


@router.post("/{model_id}/stop", response={200: Stopped, **REFUSED})
def model_stop(request, model_id: int):
    """Stop the model's training, as its page's Stop training does: a job in the queue is
    canceled; a running one saves the model of its last finished iteration, billed up to now."""
    need(request, TokenScope.TRAIN)
    job = _own(request, model_id).latest_job
    if job is None or not job.is_active:
        raise ApiError(409, "not_training", "This model is not training.")
    job = services.training_stop(job=job)
    return {"status": job.status, "message": job.message or job.failure_reason}


@router.delete("/{model_id}", response={200: Deleted, **REFUSED})
def model_delete(request, model_id: int):
    """Delete the model and every file of it, as its page's Delete does: a model that trains,
    evaluates or races is refused (409) with what to wait for."""
    need(request, TokenScope.TRAIN)
    model = _own(request, model_id)
    try:
        return {"files_removed": services.model_delete(model=model)}
    except services.ModelBusy as busy:
        raise ApiError(409, "busy", str(busy)) from None
