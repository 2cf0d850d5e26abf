"""A model's archives in the API, as its page's downloads: the physical car's, ONNX, the
virtual model's and the logs laid out as DeepRacer's (``archives.exports``, ``logs_archive``).
"""

from __future__ import annotations

from typing import Literal

from ninja import Router

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError
from api.owned import own_model
from api.schemas import REFUSED
from archives import exports, logs_archive
from training import artifacts

router = Router()

ARCHIVE = {200: {"description": "The archive", "content": {"application/gzip": {}}}}


@router.get(
    "/{model_id}/download/{kind}",
    response=REFUSED,
    openapi_extra={"responses": ARCHIVE},
)
def model_download(
    request,
    model_id: int,
    kind: Literal["physical", "onnx", "virtual", "logs"],
    checkpoint: Literal["best", "last"] = "best",
):
    """The model's archives, as its page's downloads: ``physical`` (the car's
    physicalmodel-*.tar.gz: model.pb and model_metadata.json), ``onnx``, ``virtual`` (the
    virtualmodel-*.tar.gz DeepRacer's import takes, with its best and last checkpoints) or
    ``logs`` (laid out as a DeepRacer model folder); the physical and ONNX ones of the ``best``
    or ``last`` checkpoint."""
    need(request, TokenScope.READ)
    model = own_model(request, model_id)
    try:
        if kind == "logs":
            return logs_archive.download(request, model)
        if kind == "virtual":
            export = exports.virtual(model)
        else:
            export = {"physical": exports.physical, "onnx": exports.onnx}[kind](model, checkpoint)
    except (exports.ExportRefused, logs_archive.LogsRefused) as refused:
        raise ApiError(409, "refused", str(refused)) from None
    return artifacts.download(
        request, export.name, export.filename, content_type="application/gzip"
    )
