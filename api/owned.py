"""The one access check of every operation on a model: the racer's own, or 404 (another racer's
ids are never confirmed), as ``training.selectors.model_of_racer`` is the pages'."""

from __future__ import annotations

from api.errors import ApiError
from training import selectors
from training.models import RLModel


def own_model(request, model_id: int) -> RLModel:
    model = selectors.models_for_racer(racer=request.user).filter(pk=model_id).first()
    if model is None:
        raise ApiError(404, "not_found", f"No model of yours has the id {model_id}.")
    return model
