"""The REST API, version 1, under /api/v1/ (docs/api.md; docs/decisions/0012).

Its OpenAPI 3 document is /api/v1/schema, its reference /api/v1/docs (Swagger UI from django-
ninja's own static files). Every operation keeps the pages' rules: a racer sees and changes only
their own models, and a token only what its scopes allow (``api.auth.need``).
"""

from __future__ import annotations

from datetime import datetime

from ninja import NinjaAPI, Schema

from accounts.selectors import racer_name
from api import (
    downloads,
    errors,
    evaluations,
    imports,
    league,
    race_day,
    racer_models,
    reward_functions,
    system,
    training_live,
)
from api.auth import AUTH, scopes
from api.schemas import REFUSED

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
api.add_router("/models", imports.router, tags=["imports"])
api.add_router("/models", racer_models.router, tags=["models"])
api.add_router("/models", training_live.router, tags=["training"])
api.add_router("/models", evaluations.router, tags=["evaluations"])
api.add_router("/models", downloads.router, tags=["downloads"])
api.add_router("/reward-functions", reward_functions.router, tags=["reward functions"])
api.add_router("", league.router, tags=["league"])
api.add_router("/events", race_day.router, tags=["race day"])
api.add_router("/system", system.router, tags=["staff"])


class TokenOut(Schema):
    name: str
    expires_at: datetime


class Me(Schema):
    username: str
    racer_name: str
    staff: bool
    scopes: list[str]
    token: TokenOut | None


@api.get("/me", response={200: Me, **REFUSED}, tags=["account"])
def me(request):
    """Who the request acts as, and what it may do."""
    return {
        "username": request.user.get_username(),
        "racer_name": racer_name(racer=request.user),
        "staff": request.user.is_staff,
        "scopes": sorted(scopes(request)),
        "token": getattr(request, "access_token", None),
    }
