"""Celery tasks of the league: adapters that call the racing services.

The evaluation behind a race imports torch and the simulator when it runs, so the web process,
which only enqueues, never loads them.
"""

from __future__ import annotations

from celery import shared_task

RACE_LIMIT = 3600  # [s] twenty laps of the longest track, in real time at worst


@shared_task(
    name="racing.race",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=RACE_LIMIT,
    time_limit=RACE_LIMIT + 60,
)
def race(submission_id: int) -> None:
    from racing import services

    services.submission_run(submission_id=submission_id)


@shared_task(name="racing.promote", ignore_result=True, soft_time_limit=600, time_limit=660)
def promote() -> None:
    from racing import services

    services.divisions_promote()
