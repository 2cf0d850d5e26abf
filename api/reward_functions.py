"""Reward functions in the API: Validate, as the editor's button gives it, and the racer's library
(list, read, save, change, delete), saved as the editor saves: after the same check.

The check runs in the web process's pool of checkers (training.checkers, decision 0010), from an
``async`` operation, so a request waiting on the sandbox holds no thread; counted against the
racer's ``validate`` limit as the editor's presses are.
"""

from __future__ import annotations

from datetime import datetime
from typing import Literal

from asgiref.sync import sync_to_async
from ninja import Router, Schema, Status

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError, counted, reward_checked
from api.schemas import REFUSED
from training import selectors, services
from training.forms import RewardValidationForm
from training.models import RewardFunction

router = Router()


class ValidateIn(Schema):
    source: str
    track: str = "rookie-loop"
    direction: Literal["counterclockwise", "clockwise"] = "counterclockwise"


class ProblemOut(Schema):
    type: str
    message: str
    line: int | None


class SampleOut(Schema):
    situation: str
    description: str
    reward: float | None
    error: str | None


class ValidationOut(Schema):
    valid: bool
    errors: list[ProblemOut]
    warnings: list[ProblemOut]
    samples: list[SampleOut]
    log: list[str]


@router.post("/validate", response={200: ValidationOut, **REFUSED})
async def reward_validate(request, body: ValidateIn):
    """Check a reward function as the editor's Validate does: its syntax and imports, then a run
    in the sandbox on sample situations of ``track`` (its name), with the reward of each, its
    problems by line and what it printed. ``valid`` is false for code with errors (still 200:
    the check ran); 503 with ``Retry-After`` when every checker is busy."""
    need(request, TokenScope.TRAIN)
    given = await _counted_and_read(request, body.source, body.track)
    checked = await reward_checked(
        given["source"], given["track"].name, racer=request.user.pk, direction=body.direction
    )
    return checked.as_dict()


class RewardFunctionOut(Schema):
    id: int
    name: str
    source: str
    created_at: datetime
    updated_at: datetime


class RewardFunctionIn(Schema):
    name: str
    source: str
    track: str = "rookie-loop"  # whose sample situations the check runs on


@router.get("", response={200: list[RewardFunctionOut], **REFUSED})
def reward_functions_list(request):
    """Your library of named reward functions, by name."""
    need(request, TokenScope.READ)
    return list(selectors.reward_functions_for_racer(racer=request.user))


@router.get("/{function_id}", response={200: RewardFunctionOut, **REFUSED})
def reward_function_detail(request, function_id: int):
    need(request, TokenScope.READ)
    return _own(request, function_id)


@router.post("", response={201: RewardFunctionOut, **REFUSED})
async def reward_function_create(request, body: RewardFunctionIn):
    """Save a reward function in your library, as the editor's Save does: checked first (400
    with ``errors`` by field when the name is taken or the code has errors)."""
    need(request, TokenScope.TRAIN)
    return Status(201, await _saved(request, None, body))


@router.put("/{function_id}", response={200: RewardFunctionOut, **REFUSED})
async def reward_function_update(request, function_id: int, body: RewardFunctionIn):
    """Change (or rename) one of your reward functions, checked as a new one is."""
    need(request, TokenScope.TRAIN)
    function = await sync_to_async(_own)(request, function_id)
    return await _saved(request, function, body)


@router.delete("/{function_id}", response={204: None, **REFUSED})
def reward_function_delete(request, function_id: int):
    """Take a reward function out of your library; models made with it keep their copy."""
    need(request, TokenScope.TRAIN)
    services.reward_function_delete(reward_function=_own(request, function_id))
    return Status(204, None)


def _own(request, function_id: int) -> RewardFunction:
    function = selectors.reward_functions_for_racer(racer=request.user).filter(pk=function_id)
    found = function.first()
    if found is None:
        raise ApiError(404, "not_found", f"No reward function of yours has the id {function_id}.")
    return found


async def _saved(request, function: RewardFunction | None, body: RewardFunctionIn):
    """``body`` saved (as ``function``, when it changes one), the code checked by a checker
    and counted against the racer's ``validate`` limit, as the editor's Save."""
    given = await _counted_and_read(request, body.source, body.track)
    source, track = services.reward_source(body.source), given["track"].name
    checked = await reward_checked(source, track, racer=request.user.pk) if source.strip() else None
    try:
        return await sync_to_async(services.reward_function_save)(
            owner=request.user,
            reward_function=function,
            name=body.name,
            source=source,
            track=track,
            validation=checked,
        )
    except services.RewardFunctionInvalid as invalid:
        errors = dict(invalid.errors)
        problems = invalid.validation.errors if invalid.validation else []
        if problems and "source" in errors:  # the first of the code's problems, where it is
            where = f" Line {problems[0].line}:" if problems[0].line else ""
            errors["source"] += f"{where} {problems[0].message}"
        raise ApiError(400, "invalid", "; ".join(errors.values()), errors=errors) from None


async def _counted_and_read(request, source: str, track: str) -> dict:
    """A check of ``source`` on ``track`` counted against the racer's ``validate`` limit (as
    the editor's Validate and Save count), and the two read as its form reads them; 400 for
    what the form refuses."""
    await sync_to_async(counted)(request, "validate")
    form = RewardValidationForm({"source": source, "track": track})
    if not await sync_to_async(form.is_valid)():
        raise ApiError(400, "invalid", form.first_error())
    return form.cleaned_data
