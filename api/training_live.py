"""A model's training as it happens, for scripts: its log by pages (``pitlane logs --follow``,
as DeepRacer for Cloud's ``dr-logs-sagemaker`` follows the trainer's), and its live metrics and
place in the queue as server-sent events, the messages the model page's websocket carries.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator
from datetime import datetime

from asgiref.sync import sync_to_async
from channels.layers import get_channel_layer
from django.http import StreamingHttpResponse
from ninja import Field, Query, Router, Schema

from accounts.models import TokenScope
from api.auth import need
from api.errors import ApiError
from api.owned import own_model
from api.schemas import REFUSED, named_choices
from training import selectors, streams
from training.models import JobLogLine, TrainingJob

router = Router()
LogSource = named_choices(JobLogLine.Source, "LogSource")
LOG_PAGE_MAX = 1000
REFRESH = 15.0  # [s] between fresh statuses when nothing else is said: the queue moves on


class LogLine(Schema):
    id: int
    at: datetime
    source: LogSource
    level: str
    text: str


class LogPage(Schema):
    lines: list[LogLine]
    next: int  # the ``after`` of the next page: the last line's id, or the one given
    active: bool  # whether the model's training may still write more


class LogQuery(Schema):
    after: int = Field(0, ge=0, le=2**62)  # a line's id: what every database's key holds
    limit: int = Field(500, ge=1, le=LOG_PAGE_MAX)


@router.get("/{model_id}/log", response={200: LogPage, **REFUSED})
def model_log(request, model_id: int, page: Query[LogQuery]):
    """The lines of the model's training log after the line ``after`` (an ``id``), oldest
    first, at most ``limit`` (1 to 1,000); ``next`` is the ``after`` of the next page, and
    ``active`` says whether to ask again."""
    need(request, TokenScope.READ)
    model = own_model(request, model_id)
    lines = list(
        JobLogLine.objects.filter(job__model=model, pk__gt=page.after).order_by("pk")[: page.limit]
    )
    job = model.latest_job
    return {
        "lines": lines,
        "next": lines[-1].pk if lines else page.after,
        "active": bool(job and job.is_active),
    }


@router.get("/{model_id}/training/events", response={200: None, **REFUSED})
async def training_events(request, model_id: int):
    """Server-sent events of the model's latest training (``text/event-stream``): first
    ``state`` (its status, place in the queue and every iteration so far), then each
    ``iteration`` as it is learnt and each ``status`` as it changes, a fresh ``status`` every
    15 s when nothing else is said; the stream ends once the training has ended."""
    need(request, TokenScope.READ)
    job, snapshot = await sync_to_async(_snapshot)(request, model_id)
    response = StreamingHttpResponse(_events(job, snapshot), content_type="text/event-stream")
    response["Cache-Control"] = "no-cache"
    response["X-Accel-Buffering"] = "no"  # a proxy in front passes each event on at once
    return response


def _snapshot(request, model_id: int) -> tuple[TrainingJob, dict]:
    job = own_model(request, model_id).latest_job
    if job is None:
        raise ApiError(409, "not_training", "This model has no training to follow.")
    return job, selectors.training_snapshot(job=job)


async def _events(job: TrainingJob, snapshot: dict) -> AsyncIterator[str]:
    """The events, from the job's channel-layer group (the page's websocket's), joined before
    the snapshot is sent so that nothing falls between the two."""
    layer = get_channel_layer()
    channel = await layer.new_channel()
    group = streams.training_group(job.pk)
    await layer.group_add(group, channel)
    try:
        yield _event("state", snapshot)
        active = snapshot["active"]
        while active:
            try:
                event = await asyncio.wait_for(layer.receive(channel), timeout=REFRESH)
            except TimeoutError:
                event = {"type": "job.update", "message": await _status(job.pk)}
            if event.get("type") != "job.update":
                continue  # a video frame: the page's, not a script's
            message = event["message"]
            yield _event(message.get("type", "status"), message)
            if message.get("type") == "status":
                active = message.get("active", True)
    finally:
        await layer.group_discard(group, channel)


@sync_to_async
def _status(job_id: int) -> dict:
    return selectors.training_status(job=TrainingJob.objects.select_related("model").get(pk=job_id))


def _event(kind: str, message: dict) -> str:
    return f"event: {kind}\ndata: {json.dumps(message, default=str)}\n\n"
