"""The REST API, version 1, under /api/v1/ (docs/api.md; docs/decisions/0012).

Its OpenAPI 3 document is /api/v1/schema, its reference /api/v1/docs (Swagger UI from django-
ninja's own static files). Every operation keeps the pages' rules: a racer sees and changes only
their own models, and a token only what its scopes allow (``api.auth.need``).
"""

from __future__ import annotations

from datetime import datetime

from django.db.models import Q
from ninja import NinjaAPI, Query, Schema
from ninja.errors import HttpError

from accounts.models import TokenScope
from accounts.selectors import racer_name
from api import errors
from api.auth import AUTH, need, scopes
from training import selectors
from training.models import RLModel, TrainingJob

api = NinjaAPI(
    title="Pitlane API",
    version="1",
    description="Pitlane's console for scripts and tools: see docs/api.md.",
    urls_namespace="api-v1",
    docs_url="/docs",
    openapi_url="/schema",
    auth=AUTH,
)
errors.install(api)

PAGE_MAX = 100


class Error(Schema):
    code: str
    message: str


class TokenOut(Schema):
    name: str
    expires_at: datetime


class Me(Schema):
    username: str
    racer_name: str
    staff: bool
    scopes: list[str]
    token: TokenOut | None


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


REFUSED = {400: Error, 401: Error, 403: Error, 404: Error, 429: Error}


@api.get("/me", response={200: Me, **REFUSED}, tags=["account"])
def me(request):
    """Who the request acts as, and what it may do."""
    token = getattr(request, "access_token", None)
    return {
        "username": request.user.get_username(),
        "racer_name": racer_name(racer=request.user),
        "staff": request.user.is_staff,
        "scopes": sorted(scopes(request)),
        "token": token,
    }


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


@api.get("/models", response={200: ModelPage, **REFUSED}, tags=["models"])
def models_list(request, filters: Query[ModelFilters]):
    """Your models, newest first: ``status`` and ``track`` (its name) narrow them, ``q`` finds
    names; ``limit`` (1 to 100) and ``offset`` page them."""
    need(request, TokenScope.READ)
    if not 1 <= filters.limit <= PAGE_MAX or filters.offset < 0:
        raise HttpError(400, f"limit is 1 to {PAGE_MAX}, and offset 0 or more.")
    found = selectors.models_for_racer(racer=request.user).order_by("-created_at", "-pk")
    if filters.status:
        found = found.filter(status=filters.status)
    if filters.track:
        found = found.filter(track__name=filters.track)
    if filters.q:
        found = found.filter(Q(name__icontains=filters.q) | Q(description__icontains=filters.q))
    page = found[filters.offset : filters.offset + filters.limit]
    return {"count": found.count(), "items": [_model_out(model) for model in page]}


@api.get("/models/{model_id}", response={200: ModelDetail, **REFUSED}, tags=["models"])
def model_detail(request, model_id: int):
    """One of your models, with its settings and checkpoints."""
    need(request, TokenScope.READ)
    model = selectors.models_for_racer(racer=request.user).filter(pk=model_id).first()
    if model is None:
        raise errors.ApiError(404, "not_found", f"No model of yours has the id {model_id}.")
    job = TrainingJob.objects.filter(model=model).order_by("-created_at").first()
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
