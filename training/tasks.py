"""Celery tasks of the training app: adapters that take ids and call its services."""

from __future__ import annotations

from celery import shared_task

LINE_LIMIT = 5 * 60  # [s] the longest built-in track's line takes about 10 s of CPU


@shared_task(
    name="training.racing_line",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=LINE_LIMIT,
    time_limit=LINE_LIMIT + 60,
)
def racing_line(line_id: int) -> None:
    """Compute a track's racing line (``track_lines.track_line_compute``)."""
    from training import track_lines

    track_lines.track_line_compute(line_id=line_id)
