"""Tasks of the site shell."""

from __future__ import annotations

import os
import time

from asgiref.sync import async_to_sync
from celery import shared_task
from channels.layers import get_channel_layer


@shared_task(
    name="console.probe_worker",
    bind=True,
    ignore_result=True,
    soft_time_limit=10,
    time_limit=15,
)
def probe_worker(self, reply_channel: str, queue: str, sent_at: float) -> None:
    """Answer a worker probe: which worker took the task from ``queue``, and how long it waited.

    The answer goes back over the channel layer to the websocket that asked, proving the whole
    path: web process → broker → worker → channel layer → web process → browser.
    """
    async_to_sync(get_channel_layer().send)(
        reply_channel,
        {
            "type": "probe.result",
            "queue": queue,
            "worker": self.request.hostname,
            "pid": os.getpid(),
            "waited_ms": round((time.time() - sent_at) * 1000, 1),
        },
    )
