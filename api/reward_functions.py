"""Reward functions in the API: Validate, as the editor's button gives it.

The check runs in the web process's pool of checkers (training.checkers, decision 0010), from an
``async`` operation, so a request waiting on the sandbox holds no thread; counted against the
racer's ``validate`` limit as the editor's presses are.
"""

from __future__ import annotations

from typing import Literal

from asgiref.sync import sync_to_async
from ninja import Router, Schema

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError, check_failed, counted
from api.schemas import REFUSED
from training import checkers
from training.forms import RewardValidationForm

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
    await sync_to_async(counted)(request, "validate")
    form = RewardValidationForm({"source": body.source, "track": body.track})
    if not await sync_to_async(form.is_valid)():
        raise ApiError(400, "invalid", form.first_error())
    checked = await checkers.reward_checked(
        form.cleaned_data["source"],
        form.cleaned_data["track"].name,
        racer=request.user.pk,
        direction=body.direction,
    )
    if isinstance(checked, Exception):
        raise check_failed(checked)
    return checked.as_dict()
