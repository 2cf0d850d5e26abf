"""Celery workers announce themselves in Redis, so /healthz can say which queues are served.

Each worker refreshes a key with a time-to-live every few seconds while it runs and removes it
when it stops; a worker that dies without stopping disappears when its key expires. Reading these
keys is a single round-trip to Redis, where asking workers over the broker would wait out a
timeout on every health check.
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from pathlib import Path

import redis
from celery import signals

from common.health import KEY_PREFIX
from common.redis_client import redis_client
from console.private_files import files_private, temporary_uploads_sweep

logger = logging.getLogger(__name__)

HEARTBEAT_INTERVAL = 5.0  # [s]
HEARTBEAT_TTL = 15  # [s] a worker silent this long is gone
RESUME_EVERY = 10.0  # [s] between looks for training jobs whose trainer died

_stop = threading.Event()


@signals.celeryd_init.connect
@signals.beat_init.connect
def _files_private(sender, **kwargs) -> None:
    """A worker or scheduler started on its own (not by ``make run``'s supervisor, whose umask
    its children inherit) creates its files under var/ for its owner only, too."""
    files_private()


@signals.worker_ready.connect
def _start_heartbeat(sender, **kwargs) -> None:
    record = {
        "hostname": sender.hostname,
        "pid": os.getpid(),
        "queues": sorted(queue.name for queue in sender.task_consumer.queues),
        "started_at": time.time(),
        "sandbox": {"ok": None, "detail": "checking"},
    }
    _stop.clear()
    threading.Thread(target=_beat, args=(record,), name="pitlane-heartbeat", daemon=True).start()


@signals.worker_shutdown.connect
def _stop_heartbeat(sender, **kwargs) -> None:
    _stop.set()
    try:
        redis_client().delete(KEY_PREFIX + sender.hostname)
    except redis.RedisError:
        logger.warning("Could not remove this worker's heartbeat; it expires in %ss", HEARTBEAT_TTL)


def _beat(record: dict) -> None:
    client = redis_client()
    key = KEY_PREFIX + record["hostname"]
    checked = False
    resumed_at = 0.0
    while not _stop.is_set():
        try:
            client.set(key, json.dumps(record), ex=HEARTBEAT_TTL)
        except redis.RedisError as error:
            logger.warning("Worker heartbeat failed: %s", error)
        if time.monotonic() - resumed_at >= RESUME_EVERY:
            resumed_at = time.monotonic()
            _resume_lapsed()
            _sweep_temporary_uploads()
        if not checked:
            record["sandbox"] = _check_sandbox()
            checked = True
            continue  # report the result at once
        _stop.wait(HEARTBEAT_INTERVAL)


def _resume_lapsed() -> None:
    """Send for the jobs whose trainer died, and the evaluations whose simulation worker died
    (``console.recovery.resume_lapsed``). Any worker may: whichever looks first claims each, so
    it is sent for once, and the work goes on as long as one worker of either queue is alive."""
    from django.db import DatabaseError, close_old_connections
    from kombu.exceptions import OperationalError

    from console.recovery import resume_lapsed

    close_old_connections()
    try:
        for sent in resume_lapsed():
            logger.warning("The %s", sent)
    except (DatabaseError, redis.RedisError, OperationalError) as error:
        logger.warning("Could not look for work that lost its worker: %s", error)
    finally:
        close_old_connections()


def _sweep_temporary_uploads() -> None:
    """Delete the temporary uploads a killed web server left on this machine
    (``private_files.temporary_uploads_sweep``)."""
    from django.conf import settings

    try:
        for deleted in temporary_uploads_sweep(Path(settings.FILE_UPLOAD_TEMP_DIR)):
            logger.warning("A %s", deleted)
    except OSError as error:
        logger.warning("Could not sweep the temporary uploads: %s", error)


def _check_sandbox() -> dict:
    """The sandbox self-test, logged: a worker whose sandbox does not hold refuses racers' code."""
    from sandbox import self_test

    result = self_test()
    if result.ok:
        logger.info("Sandbox self-test: %s", result.detail)
    else:
        logger.error("Sandbox self-test FAILED, racers' code will be refused: %s", result.detail)
    return {"ok": result.ok, "detail": result.detail}
