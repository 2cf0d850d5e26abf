"""The live stream of a training job or an evaluation, for its owner (and staff).

``ws/jobs/<id>/`` (training) and ``ws/evaluations/<id>/``. On connecting, the viewer gets the
whole current state at once (a ``state`` message, then the newest frame of the view it watches),
then ``status`` and ``iteration`` messages as JSON text, in the order they were sent, and frames as
binary messages (see ``training.streams``), sent as the publisher built them.

Frames are flow-controlled: at most ``WINDOW`` are in flight to the browser, each released by the
page's ``{"type": "ack"}`` once it has drawn the frame. Frames that come meanwhile replace one
another, so a slow viewer gets the newest frame next, never a backlog, and holds one frame at
most. The page chooses what to watch with ``{"type": "watch", "worker": N, "view": "spectator"|
"camera"}``.
"""

from __future__ import annotations

import asyncio
import functools
import json

import redis
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer

from common.redis_client import redis_client
from common.sockets import ClosesOnLayerOutage
from training import selectors, streams
from training.models import EvaluationJob, TrainingJob

WINDOW = 2  # frames sent and not yet acknowledged
REFUSED_ANONYMOUS = 4401
REFUSED_FORBIDDEN = 4403


@functools.cache
def _viewers_redis() -> redis.Redis:
    """One client (and connection pool) for every viewer this server process holds."""
    return redis_client(timeout=2.0)


class LiveConsumer(ClosesOnLayerOutage, AsyncWebsocketConsumer):
    """What the training and evaluation streams share: who may watch, flow control, viewers."""

    workers = 1
    anonymous = False  # whether a visitor who has not logged in may watch (``snapshot_for``)

    async def connect(self) -> None:
        user = self.scope.get("user")
        if user is None or not (user.is_authenticated or self.anonymous):
            await self.close(code=REFUSED_ANONYMOUS)
            return
        pk = self.scope["url_route"]["kwargs"]["pk"]
        # The group is joined before the state is read: an update the worker stores and
        # announces in between then reaches this viewer (after the state, which may already
        # hold it), rather than falling between the two and leaving the page behind the job.
        group = self.group_for(pk)
        await self.channel_layer.group_add(group, self.channel_name)
        snapshot = await database_sync_to_async(self.snapshot_for)(user, pk)
        if snapshot is None:
            await self.channel_layer.group_discard(group, self.channel_name)
            await self.close(code=REFUSED_FORBIDDEN)
            return
        self.group = group
        self.stream = streams.Stream(_viewers_redis(), self.group)
        self.worker, self.view = 0, "spectator"
        self.in_flight, self.pending = 0, None
        await self._redis(self.stream.watch, self.channel_name, self.worker, self.view)
        await self.accept()
        await self.send(text_data=json.dumps(snapshot))
        await self._show_latest()
        self.renewer = asyncio.create_task(self._renew())

    async def disconnect(self, code: int) -> None:
        renewer = getattr(self, "renewer", None)
        if renewer is None:
            return
        renewer.cancel()
        await self.channel_layer.group_discard(self.group, self.channel_name)
        await self._redis(self.stream.unwatch, self.channel_name)

    async def receive(self, text_data: str | None = None, bytes_data: bytes | None = None) -> None:
        try:
            message = json.loads(text_data or "")
        except ValueError:
            return
        if not isinstance(message, dict):
            return
        if message.get("type") == "ack":
            self.in_flight = max(self.in_flight - 1, 0)
            await self._flush()
        elif message.get("type") == "watch":
            worker, view = message.get("worker"), message.get("view")
            if isinstance(worker, int) and 0 <= worker < self.workers and view in streams.VIEWS:
                self.worker, self.view, self.pending = worker, view, None
                await self._redis(self.stream.watch, self.channel_name, worker, view)
                await self._show_latest()

    # Events from the channel layer

    async def job_frame(self, event: dict) -> None:
        if event.get("worker") == self.worker and event.get("view") == self.view:
            self.pending = event
            await self._flush()

    async def job_update(self, event: dict) -> None:
        message = event["message"]
        if message.get("type") == "status":
            self.workers = message.get("workers", self.workers)
        await self.send(text_data=json.dumps(message))

    # Helpers

    async def _flush(self) -> None:
        if self.pending is None or self.in_flight >= WINDOW:
            return
        frame, self.pending = self.pending, None
        self.in_flight += 1
        await self.send(bytes_data=frame["data"])

    async def _show_latest(self) -> None:
        """The newest frame of what this viewer watches, at once, rather than at the next."""
        frame = await self._redis(self.stream.latest_frame, self.worker, self.view)
        if frame is not None and self.pending is None:
            self.pending = frame
            await self._flush()

    async def _renew(self) -> None:
        while True:
            await asyncio.sleep(streams.VIEWER_RENEW)
            await self._redis(self.stream.watch, self.channel_name, self.worker, self.view)

    async def _redis(self, function, *args):
        """A call to Redis off the event loop; a Redis that is down costs the frames, not the
        page."""
        try:
            return await sync_to_async(function, thread_sensitive=False)(*args)
        except redis.RedisError:
            return None

    # What each stream defines

    def group_for(self, pk: int) -> str:
        raise NotImplementedError

    def snapshot_for(self, user, pk: int) -> dict | None:
        """The state message for ``user``, or None when they may not watch."""
        raise NotImplementedError


class TrainingConsumer(LiveConsumer):
    def group_for(self, pk: int) -> str:
        return streams.training_group(pk)

    def snapshot_for(self, user, pk: int) -> dict | None:
        job = TrainingJob.objects.select_related("model").filter(pk=pk).first()
        if job is None or not (job.model.owner_id == user.pk or user.is_staff):
            return None
        self.workers = job.model.workers
        return selectors.training_snapshot(job=job)


class EvaluationConsumer(LiveConsumer):
    def group_for(self, pk: int) -> str:
        return streams.evaluation_group(pk)

    def snapshot_for(self, user, pk: int) -> dict | None:
        evaluation = EvaluationJob.objects.select_related("model").filter(pk=pk).first()
        if evaluation is None or not (evaluation.model.owner_id == user.pk or user.is_staff):
            return None
        return selectors.evaluation_snapshot(evaluation=evaluation)
