"""Websocket consumers of the site shell."""

from __future__ import annotations

import time

from asgiref.sync import sync_to_async
from channels.generic.websocket import AsyncJsonWebsocketConsumer
from django.conf import settings
from kombu.exceptions import OperationalError

from common.sockets import ClosesOnLayerOutage
from console.tasks import probe_worker

PROBE_EXPIRES = 30  # [s] a probe no worker took by then is dropped, not run late


class WorkerProbeConsumer(ClosesOnLayerOutage, AsyncJsonWebsocketConsumer):
    """Staff only: ``{"action": "probe"}`` probes every queue and relays the answers."""

    async def connect(self) -> None:
        user = self.scope.get("user")
        if user is None or not user.is_active or not user.is_staff:
            await self.close(code=4403)
            return
        await self.accept()

    async def receive_json(self, content, **kwargs) -> None:
        if content.get("action") != "probe":
            await self.send_json({"type": "error", "message": "Unknown action."})
            return
        sent_at = time.time()
        try:
            for queue in settings.PITLANE_QUEUES:
                await sync_to_async(probe_worker.apply_async)(
                    args=[self.channel_name, queue, sent_at], queue=queue, expires=PROBE_EXPIRES
                )
        except OperationalError:
            await self.send_json(
                {"type": "error", "message": "The probe could not be queued: Redis is unreachable."}
            )
            return
        await self.send_json({"type": "probe.sent", "queues": list(settings.PITLANE_QUEUES)})

    async def probe_result(self, event: dict) -> None:
        await self.send_json(event)
