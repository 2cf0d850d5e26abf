"""The jobs' Celery tasks: adapters that take ids and call the trainer, a rollout worker or an
evaluation's run, and what reads the broker's queues for them.

Their names are training's (``training.train``, ``training.rollout``, ``training.evaluate``):
messages already in a broker keep being understood, and services queue them by those names
(``common.queueing``), never importing this module. The trainer and rollout modules (torch, the
simulator) are imported when a task runs, so a worker that only serves other queues never loads
them.
"""

from __future__ import annotations

import base64
import json
import os

from celery import shared_task

LONGEST_JOB = 24 * 3600  # [s] the longest training time a racer may ask for
EVALUATION_LIMIT = 3600  # [s] five trials of at most 10,000 steps each, in real time at worst


@shared_task(
    name="training.train",
    bind=True,
    acks_late=True,
    ignore_result=True,
    soft_time_limit=LONGEST_JOB + 900,
    time_limit=LONGEST_JOB + 1200,
)
def train(self, job_id: int) -> None:
    from jobs import trainer

    torch_threads()
    owner = f"{self.request.hostname}:{os.getpid()}"
    if not trainer.run(
        job_id, owner=owner, start_rollouts=start_rollout, queued_rollouts=queued_rollouts
    ):
        # Another run holds the job: a duplicate delivery, or a redelivery after that run's
        # worker died. Look again when its lease would have lapsed; never train twice.
        from django.conf import settings

        raise self.retry(countdown=settings.PITLANE_TRAINER_LEASE + 5, max_retries=None)


@shared_task(
    name="training.rollout",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=LONGEST_JOB + 900,
    time_limit=LONGEST_JOB + 1200,
)
def rollout(job_id: int, worker: int, attempt: int, track: str) -> None:
    from jobs import rollouts

    rollouts.run(job_id, worker, attempt, track)


@shared_task(
    name="training.evaluate",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=EVALUATION_LIMIT,
    time_limit=EVALUATION_LIMIT + 60,
)
def evaluate(evaluation_id: int) -> None:
    from jobs import evaluation

    evaluation.run(evaluation_id)


def waiting() -> dict[str, set[int]] | None:
    """The tasks waiting in the broker's queues, by name: the first argument (a row's id) of
    each message; None when the broker is not one whose queues can be read (Redis)."""
    messages = _queued_messages()
    if messages is None:
        return None
    found: dict[str, set[int]] = {}
    for name, args in messages:
        found.setdefault(name, set()).add(args[0] if args else None)
    return found


def queued_rollouts(job) -> set[int] | None:
    """The slots of ``job``'s run (its attempt) whose rollout task waits in the broker's queue,
    not yet taken by a simulation worker; None when the broker's queues cannot be read."""
    messages = _queued_messages()
    if messages is None:
        return None
    return {
        args[1]
        for name, args in messages
        if name == rollout.name and len(args) == 4 and args[0] == job.pk and args[2] == job.attempt
    }


def _queued_messages() -> list[tuple[str, list]] | None:
    """(task name, arguments) of each message waiting in the broker's queues; None when the
    broker is not one whose queues can be read (Redis)."""
    from celery import current_app

    with current_app.connection_for_read() as connection:
        channel = connection.default_channel
        if not hasattr(channel, "_q_for_pri"):
            return None
        queues = {route["queue"] for route in current_app.conf.task_routes.values()}
        queues.add(current_app.conf.task_default_queue)
        prefix = getattr(channel, "global_keyprefix", "") or ""  # LRANGE is not prefixed for us
        found = []
        for queue in queues:
            for priority in channel.priority_steps:  # kombu keeps a list per priority
                key = prefix + channel._q_for_pri(queue, priority)
                found += [_task_of(raw) for raw in channel.client.lrange(key, 0, -1)]
    return [(name, args) for name, args in found if name]


def _task_of(raw: bytes) -> tuple[str, list]:
    """(task name, arguments) of a message as kombu's Redis transport stores it."""
    try:
        message = json.loads(raw)
        body = message["body"]
        if message.get("properties", {}).get("body_encoding") == "base64":
            body = base64.b64decode(body)
        args = json.loads(body)[0]
        return message["headers"]["task"], list(args)
    except (ValueError, KeyError, IndexError, TypeError):
        return "", []


def torch_threads() -> None:
    """The trainer's threads: every core by default, as it learns only while the rollout workers
    wait for its new weights; the setting keeps a share for a machine that runs more."""
    import torch
    from django.conf import settings

    torch.set_num_threads(settings.PITLANE_TRAINER_THREADS)


def start_rollout(job, slot) -> None:
    """Enqueue the rollout worker for ``slot`` of ``job`` (a ``trainer.Slot``)."""
    rollout.delay(job.pk, slot.index, job.attempt, slot.track)
