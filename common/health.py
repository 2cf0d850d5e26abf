"""Reachability of what the console depends on: the database, Redis and the Celery workers
(which announce themselves in Redis: ``console.workers`` writes the heartbeats, ``live_workers``
reads them), for /healthz, the System page and the API's."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

import redis
from django.conf import settings
from django.db import DatabaseError, connection

from common.redis_client import redis_client

KEY_PREFIX = "pitlane:worker:"  # a worker's heartbeat, by its hostname


def live_workers(client: redis.Redis) -> list[dict]:
    """The workers whose heartbeat has not expired: hostname, pid, queues, started_at."""
    keys = sorted(client.scan_iter(match=f"{KEY_PREFIX}*", count=100))
    return [json.loads(value) for value in client.mget(keys) if value] if keys else []


class Down(Exception):
    """A dependency is unreachable; the message says how, for an operator."""


def check_database() -> dict[str, Any]:
    try:
        with connection.cursor() as cursor:
            cursor.execute("SELECT 1")
            cursor.fetchone()
    except DatabaseError as error:
        raise Down(f"cannot query the database: {error}") from None
    return {"vendor": connection.vendor}


def check_redis() -> dict[str, Any]:
    try:
        info = redis_client().info("server")
    except redis.RedisError as error:
        raise Down(f"cannot reach Redis: {error}") from None
    return {"version": info.get("redis_version")}


def check_workers() -> dict[str, Any]:
    try:
        workers = live_workers(redis_client())
    except redis.RedisError:
        raise Down("unknown: the workers report through Redis, which is down") from None
    served = {queue for worker in workers for queue in worker["queues"]}
    missing = [queue for queue in settings.PITLANE_QUEUES if queue not in served]
    if not workers:
        raise Down("no Celery worker is running")
    if missing:
        raise Down(f"no Celery worker serves the {', '.join(missing)} queue")
    sandboxes = [w.get("sandbox", {}) for w in workers if "simulation" in w["queues"]]
    if all(sandbox.get("ok") is False for sandbox in sandboxes):
        detail = sandboxes[0].get("detail", "unknown")
        raise Down(
            f"no worker can run racers' code safely: its sandbox self-test failed ({detail})"
        )
    return {
        "workers": [
            {"hostname": w["hostname"], "queues": w["queues"], "sandbox": w.get("sandbox")}
            for w in workers
        ],
    }


CHECKS: dict[str, Callable[[], dict[str, Any]]] = {
    "database": check_database,
    "redis": check_redis,
    "workers": check_workers,
}


def system_health() -> dict[str, Any]:
    """Every check's result: ``{"status": "ok" | "down", "down": [...], "checks": {...}}``."""
    checks: dict[str, dict[str, Any]] = {}
    for name, check in CHECKS.items():
        started = time.perf_counter()
        try:
            result = {"ok": True, **check()}
        except Down as error:
            result = {"ok": False, "error": str(error)}
        result["latency_ms"] = round((time.perf_counter() - started) * 1000, 1)
        checks[name] = result
    down = [name for name, result in checks.items() if not result["ok"]]
    return {"status": "down" if down else "ok", "down": down, "checks": checks}
