"""What the model commands share: finding a model by its name (or number) and racer, and
checking that Redis answers before a command queues work."""

from __future__ import annotations

import redis
from django.conf import settings
from django.contrib.auth import get_user_model
from django.core.management.base import CommandError
from kombu.utils.url import maybe_sanitize_url

from training.models import RLModel


def find_model(name: str, owner: str | None) -> RLModel:
    """The model called ``name`` (or numbered so), of ``owner`` when given; ``CommandError``
    when there is none, or several racers have one of that name."""
    models = RLModel.objects.select_related("owner", "track")
    if owner:
        racer = find_racer(owner)
        models = models.filter(owner=racer)
    found = list(models.filter(pk=int(name)) if name.isdigit() else models.filter(name=name))
    if not found:
        raise CommandError(f"No model named {name!r}" + (f" of {owner}." if owner else "."))
    if len(found) > 1:
        raise CommandError(f"Several racers have a model named {name!r}; add --owner.")
    return found[0]


def find_racer(username: str):
    racer = get_user_model().objects.filter(username=username).first()
    if racer is None:
        raise CommandError(f"No racer named {username!r}.")
    return racer


def redis_check(nothing_done: str) -> None:
    """``CommandError`` in words when Redis, Celery's broker, does not answer, for a command that
    queues work (a training) to call before it changes anything: it then stops with nothing
    done (``nothing_done`` says so) rather than leave work whose task could not be sent."""
    broker = settings.CELERY_BROKER_URL
    where = maybe_sanitize_url(broker)  # its password masked
    try:
        redis.Redis.from_url(broker, socket_connect_timeout=2.0, socket_timeout=2.0).ping()
    except (redis.ConnectionError, redis.TimeoutError):
        raise CommandError(
            f"Redis at {where} does not answer: start it (make run does) and try again. "
            f"{nothing_done}"
        ) from None
    except redis.RedisError as error:
        raise CommandError(f"Redis at {where} refuses: {error}. {nothing_done}") from None
