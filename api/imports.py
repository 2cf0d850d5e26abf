"""Importing a model through the API, with the import page's steps and rules
(``archives.imports``): an archive that brings its weights arrives at once (201); one that would
train is previewed first (200, the archive kept for the racer as the page keeps it), and created,
its training queued, once confirmed with the name, track, direction and time the racer may
change. The racer's import limits count as the page's, and the archive is read by a checker.
"""

from __future__ import annotations

from typing import Literal

from asgiref.sync import sync_to_async
from ninja import File, Form, Router, Schema, Status
from ninja.files import UploadedFile

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError, check_failed, rate_refusal
from api.racer_models import Created, model_detail
from api.schemas import REFUSED, Error
from archives import imports, kept_uploads
from common import ratelimits
from common.refusals import Refused
from training import checkers, configuration

router = Router()
TOO_LARGE = {**REFUSED, 413: Error}


class Preview(Schema):
    """What the import would create: its settings in the console's names, the notes on what it
    reads differently or leaves out, the problems to fix before it can be confirmed (by
    setting), and ``kept``, the token that names the archive kept for the confirmation."""

    kept: str
    settings: dict
    notes: list[str]
    problems: dict[str, str]


class ConfirmIn(Schema):
    kept: str
    name: str | None = None
    track: str | None = None
    direction: Literal["counterclockwise", "clockwise"] | None = None
    max_minutes: int | None = None


class Cancelled(Schema):
    cancelled: str | None  # the archive's file name, None when none was kept


@router.post("/import", response={201: Created, 200: Preview, **TOO_LARGE}, url_name="model-import")
async def model_import(request, archive: File[UploadedFile], name: Form[str] = ""):
    """Import a model from an archive (a Pitlane virtual model, a model downloaded from
    DeepRacer's console, or DeepRacer for Cloud's model folder packed as a tar): 201 with the
    model when it brings its weights; else 200 with its preview, to ``confirm``."""
    need(request, TokenScope.TRAIN)
    name = name.strip()
    if name and (
        problem := await sync_to_async(configuration.name_problem)(name, owner=request.user)
    ):
        raise ApiError(400, "invalid", problem, errors={"name": problem})
    if archive.size > imports.MAX_ARCHIVE:
        raise ApiError(
            413, "too_large", f"The archive is over {imports.size(imports.MAX_ARCHIVE)}."
        )
    owner = request.user

    def work():
        return imports.import_start(owner=owner, archive=archive, name=name)

    outcome = await _attempt(request, work)
    if isinstance(outcome, imports.ImportPreview):
        return await sync_to_async(_previewed)(request, outcome, archive)
    return await _answered(request, outcome)


@router.post("/import/confirm", response={201: Created, **REFUSED})
async def model_import_confirm(request, body: ConfirmIn):
    """Create the previewed model, with the changes given, and queue its training: what is not
    given is the archive's (its name too: send the preview's again where you chose one); 400
    with the problems left, 409 when the kept archive is gone."""
    need(request, TokenScope.TRAIN)
    owner = request.user
    kept = await sync_to_async(kept_uploads.upload_kept)(racer=owner, token=body.kept)
    if kept is None:
        raise ApiError(409, "gone", kept_uploads.KEPT_GONE)
    changes = body.dict(exclude_none=True, exclude={"kept"})

    def work():
        with kept_uploads.upload_open(kept) as archive:
            return imports.import_start(
                owner=owner, archive=archive, changes=changes, confirmed=True
            )

    outcome = await _attempt(request, work)
    if isinstance(outcome, imports.ImportPreview):
        raise ApiError(400, "invalid", _problems_words(outcome.problems), errors=outcome.problems)
    return await _answered(request, outcome)


@router.delete("/import", response={200: Cancelled, **REFUSED})
def model_import_cancel(request):
    """Delete the archive kept for your import's confirmation, as the page's Cancel does."""
    need(request, TokenScope.TRAIN)
    kept = kept_uploads.upload_discard(racer=request.user)
    return {"cancelled": kept.filename if kept else None}


async def _attempt(request, work):
    """``work``'s outcome, by a checker, counted against the racer's import limits as the page
    counts an attempt: the import, its preview, or its refusal (raised in the API's words)."""
    held = await sync_to_async(ratelimits.hold)(request, "import", "import-refused")
    if held.limited:
        raise rate_refusal(held.limited)
    try:
        outcome = await checkers.run(work, racer=request.user.pk)
    except (Refused, *checkers.FAILURES) as error:
        outcome = error
    await sync_to_async(imports.attempt_counted)(held, outcome)
    if isinstance(outcome, checkers.FAILURES):
        raise check_failed(outcome)
    if isinstance(outcome, configuration.Invalid):
        raise ApiError(400, "invalid", str(outcome), errors=outcome.errors)
    if isinstance(outcome, Refused):
        raise ApiError(400, "refused", str(outcome), errors=outcome.errors)
    return outcome


async def _answered(request, outcome: imports.Imported) -> Status:
    await sync_to_async(kept_uploads.upload_discard)(racer=request.user)
    detail = await sync_to_async(model_detail)(request, outcome.model.pk)
    return Status(201, {**detail, "notes": outcome.notes})


def _previewed(request, preview: imports.ImportPreview, archive: UploadedFile) -> dict:
    try:
        kept = kept_uploads.upload_keep(racer=request.user, upload=archive)
    except kept_uploads.UploadNotKept as refused:
        if refused.retry_after is None:
            raise ApiError(413, "too_large", str(refused)) from None
        raise ApiError(
            503, "unavailable", str(refused), {"Retry-After": str(refused.retry_after)}
        ) from None
    settings = {key: value for key, value in preview.settings.items() if _shown(value)}
    return {
        "kept": kept.token,
        "settings": settings,
        "notes": preview.notes,
        "problems": preview.problems,
    }


def _shown(value) -> bool:
    """Whether a setting's value is plain data (a clone's source model is not)."""
    return value is None or isinstance(value, str | int | float | bool | list | dict)


def _problems_words(problems: dict[str, str]) -> str:
    return "; ".join(f"{setting}: {message}" for setting, message in problems.items())
