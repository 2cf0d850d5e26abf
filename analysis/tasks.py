"""Celery tasks of the analysis: adapters that load ids and call the runner."""

from __future__ import annotations

from celery import shared_task

RESCORE_LIMIT = 15 * 60  # [s] a re-scoring is stopped after this, and told so
RESCORE_HARD_LIMIT = RESCORE_LIMIT + 60  # [s] its worker process is killed after this


@shared_task(
    name="analysis.rescore",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=RESCORE_LIMIT,
    time_limit=RESCORE_HARD_LIMIT,
)
def rescore(rescoring_id: int | None = None) -> None:
    """Run the next re-scoring in turn, by racer (``rescoring.run_next``): ``rescoring_id``,
    the one whose asking queued this task, is not necessarily it."""
    from analysis import rescoring

    rescoring.run_next()
