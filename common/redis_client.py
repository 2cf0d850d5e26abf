"""The Redis client for Pitlane's own keys (jobs, live streams, worker heartbeats)."""

from __future__ import annotations

import redis
from django.conf import settings


def redis_client(timeout: float = 1.0) -> redis.Redis:
    """A Redis client for Pitlane's own keys, failing fast when Redis is unreachable; commands
    that block (such as BLPOP) need a ``timeout`` longer than they wait."""
    return redis.Redis.from_url(
        settings.REDIS_URL, socket_connect_timeout=2.0, socket_timeout=timeout
    )
