"""What racers watch live: spectator and camera frames, iterations and job status, sent to a job's
channel group (``job_<id>`` for training, ``evaluation_<id>`` for an evaluation).

Frames are produced only while someone watches: each connected viewer registers in the stream's
``viewers`` hash in Redis (which worker and which view, with an expiry it keeps renewing), and the
simulation renders a view only while a live registration asks for it. The simulation hands its
frames to a ``FramePublisher``, whose own thread sends them, newest first: the simulation never
waits on the channel layer, and a frame not yet sent when the next one comes is replaced, not
queued. Each viewer's consumer does the same on its side (see ``training.consumers``).

A frame goes to the page as one binary websocket message: a 4-byte big-endian length, a JSON
header of that length (worker, view, seq, rendered_at, episode, step, status, progress, paused),
then the JPEG. The publisher builds it once; the channel layer carries it once to each server
process (channels_redis groups a message's channels by process), and every viewer there is sent
the same bytes.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import struct
import threading
import time
from collections.abc import Callable
from typing import Any

import redis
from asgiref.sync import async_to_sync
from channels import DEFAULT_CHANNEL_LAYER
from channels.layers import channel_layers, get_channel_layer

from common.numbers import finite
from simulator.config import VIEWS

logger = logging.getLogger(__name__)

VIEWER_TTL = 15.0  # [s] a viewer's registration lives this long unless renewed
VIEWER_RENEW = 5.0  # [s] between a consumer's renewals
FRAME_KEEP = 60  # [s] the newest frame of each view is kept for viewers who connect
MAX_JPEG = 1024 * 1024  # [bytes] a frame from a sandbox child beyond this is dropped
HEADER_LENGTH = struct.Struct("!I")


def training_group(job_id: int) -> str:
    return f"job_{job_id}"


def evaluation_group(evaluation_id: int) -> str:
    return f"evaluation_{evaluation_id}"


class Stream:
    """A group's live keys in Redis: who watches what, and the newest frame of each view."""

    def __init__(self, client: redis.Redis, group: str) -> None:
        self.client = client
        self.group = group
        self.viewers = f"pitlane:live:{group}:viewers"

    def watch(self, viewer: str, worker: int, view: str) -> None:
        """Register (or renew) ``viewer``, a consumer's channel name, as watching ``view`` of
        ``worker``."""
        pipe = self.client.pipeline()
        pipe.hset(self.viewers, viewer, f"{worker}:{view}:{time.time() + VIEWER_TTL:.3f}")
        pipe.expire(self.viewers, int(VIEWER_TTL * 4))
        pipe.execute()

    def unwatch(self, viewer: str) -> None:
        self.client.hdel(self.viewers, viewer)

    def wanted(self, worker: int) -> set[str]:
        """The views of ``worker`` that someone watches now; forgets registrations that lapsed
        (a consumer whose server died never unregistered)."""
        now, views, lapsed = time.time(), set(), []
        for viewer, value in self.client.hgetall(self.viewers).items():
            try:
                index, view, expires = value.decode().split(":")
                if float(expires) < now:
                    lapsed.append(viewer)
                elif int(index) == worker and view in VIEWS:
                    views.add(view)
            except (UnicodeDecodeError, ValueError):
                lapsed.append(viewer)
        if lapsed:
            self.client.hdel(self.viewers, *lapsed)
        return views

    def keep_frame(self, message: dict) -> None:
        """Keep ``message``, a ``job.frame`` event, for viewers who connect later."""
        self.client.set(
            self._frame_key(message["worker"], message["view"]), message["data"], ex=FRAME_KEEP
        )

    def latest_frame(self, worker: int, view: str) -> dict | None:
        data = self.client.get(self._frame_key(worker, view))
        return frame_message(worker, view, data) if data else None

    def _frame_key(self, worker: int, view: str) -> str:
        return f"pitlane:live:{self.group}:frame:{worker}:{view}"


def frame_event(worker: int, view: str, jpeg: bytes, **details) -> dict:
    """A frame as the simulation offers it to a ``FramePublisher``. ``details``: what the page
    shows with it (episode, step, status, progress, paused)."""
    return {"worker": worker, "view": view, "rendered_at": time.time(), "jpeg": jpeg, **details}


def frame_message(worker: int, view: str, data: bytes) -> dict:
    """The ``job.frame`` event the channel layer carries: ``data`` is the page's message."""
    return {"type": "job.frame", "worker": worker, "view": view, "data": data}


def pack_frame(frame: dict) -> dict:
    """The ``job.frame`` event of ``frame`` (from ``frame_event``), its message built once."""
    header = json.dumps({key: value for key, value in frame.items() if key != "jpeg"}).encode()
    data = HEADER_LENGTH.pack(len(header)) + header + frame["jpeg"]
    return frame_message(frame["worker"], frame["view"], data)


def frame_from_child(raw: dict[str, Any], worker: int) -> dict | None:
    """A frame (as ``frame_event`` makes one) from what a sandbox child sent, or None if it is
    not one: the child ran a racer's code, so only checked fields of known types go on."""
    data, view = raw.get("jpeg"), raw.get("view")
    if view not in VIEWS or not isinstance(data, bytes) or len(data) > MAX_JPEG:
        return None
    if not data.startswith(b"\xff\xd8\xff"):
        return None
    now, rendered = time.time(), raw.get("rendered_at")
    event = frame_event(
        worker,
        view,
        data,
        episode=_number(raw.get("episode"), int),
        step=_number(raw.get("step"), int),
        progress=_number(raw.get("progress"), float),
        status=str(raw.get("status", ""))[:20],
    )
    if isinstance(rendered, float) and now - 5.0 <= rendered <= now:
        event["rendered_at"] = rendered
    return event


def _number(value: Any, kind: type) -> int | float:
    """A number a child sent, of ``kind``; 0 for anything else (text, a bool, NaN)."""
    number = None if isinstance(value, bool | str) else finite(value)
    return kind(number or 0)


def send(group: str, message: dict) -> None:
    """Send ``message`` to ``group`` from synchronous code; a channel layer that is down costs
    the viewers an update, never the job."""
    try:
        async_to_sync(get_channel_layer().group_send)(group, message)
    except (OSError, redis.RedisError) as error:
        logger.warning("Could not send %s to %s: %s", message.get("type"), group, error)


class FramePublisher:
    """Sends a group's frames from its own thread, newest first.

    ``offer`` never blocks: it leaves the frame in a one-frame mailbox per (worker, view),
    replacing one the thread has not sent yet. ``watched`` tells the simulation which views
    someone watches, from the stream's registrations, looked at once a second at most.
    """

    LOOK_EVERY = 1.0  # [s]

    def __init__(self, client: redis.Redis, group: str) -> None:
        self.stream = Stream(client, group)
        self.group = group
        self._mailbox: dict[tuple[int, str], dict] = {}
        self._numbers = itertools.count(1)
        self._condition = threading.Condition()
        self._closed = False
        self._views: dict[int, tuple[float, set[str]]] = {}
        self._thread = threading.Thread(target=self._run, name=f"frames-{group}", daemon=True)
        self._thread.start()

    def watched(self, worker: int) -> set[str]:
        looked, views = self._views.get(worker, (0.0, set()))
        if time.monotonic() - looked >= self.LOOK_EVERY:
            try:
                views = self.stream.wanted(worker)
            except redis.RedisError:
                views = set()
            self._views[worker] = (time.monotonic(), views)
        return views

    def offer(self, frame: dict) -> None:
        """Send ``frame`` (from ``frame_event``) soon, numbered in the order offered."""
        with self._condition:
            frame["seq"] = next(self._numbers)
            self._mailbox[(frame["worker"], frame["view"])] = frame
            self._condition.notify()

    def close(self) -> None:
        with self._condition:
            self._closed = True
            self._condition.notify()
        self._thread.join(timeout=5.0)

    def __enter__(self) -> FramePublisher:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        # A layer of its own: the process's shared one may serve other event loops, and closing
        # its connections here would close theirs.
        layer = channel_layers.make_backend(DEFAULT_CHANNEL_LAYER)
        try:
            while True:
                with self._condition:
                    self._condition.wait_for(lambda: self._mailbox or self._closed)
                    if not self._mailbox:
                        return
                    frames, self._mailbox = list(self._mailbox.values()), {}
                for frame in frames:
                    self._deliver(loop, layer, frame)
        finally:
            close_pools: Callable | None = getattr(layer, "close_pools", None)
            if close_pools is not None:
                loop.run_until_complete(close_pools())
            loop.close()

    def _deliver(self, loop: asyncio.AbstractEventLoop, layer, frame: dict) -> None:
        message = pack_frame(frame)
        try:
            loop.run_until_complete(layer.group_send(self.group, message))
            self.stream.keep_frame(message)
        except (OSError, redis.RedisError) as error:
            logger.warning("A frame for %s was not sent: %s", self.group, error)


# What the trainer and the services announce


def announce(group: str, message: dict) -> None:
    """A ``status``, ``iteration`` or ``state`` message for the page, in the order sent."""
    send(group, {"type": "job.update", "message": message})


def announce_training(job_id: int) -> None:
    """Send a training job's status to its viewers."""
    from training import selectors
    from training.models import TrainingJob

    job = TrainingJob.objects.select_related("model").filter(pk=job_id).first()
    if job is not None:
        announce(training_group(job.pk), selectors.training_status(job=job))


def announce_queue() -> None:
    """A job left the queue: the jobs still waiting have moved up, and those training share the
    machine with one more (``selectors.sharing_words``)."""
    from training.models import TrainingJob

    for job_id in TrainingJob.objects.filter(status__in=TrainingJob.ACTIVE).values_list(
        "pk", flat=True
    ):
        announce_training(job_id)


def announce_iteration(job_id: int, number: int) -> None:
    from training import selectors
    from training.models import Iteration

    row = Iteration.objects.filter(job_id=job_id, number=number).first()
    if row is not None:
        announce(training_group(job_id), selectors.iteration_point(row=row))
