"""What the league tells the pages that watch it, over the ``event_<id>`` channel group.

A leaderboard page listens to its event's group; when a submission is scored, disqualified or
removed, it hears a ``leaderboard`` message and fetches its table again. The racer's own
submission page hears its ``submission`` messages (status, then the score).
"""

from __future__ import annotations

from django.db import transaction

from racing.models import Event, Submission
from training import live


def event_group(event_id: int) -> str:
    return f"event_{event_id}"


def announce_leaderboard(event: Event, **details) -> None:
    """The event's rankings changed: after the change is committed, every page that shows them
    hears it."""
    message = {"type": "leaderboard", "event": event.pk, **details}
    transaction.on_commit(lambda: live.send(event_group(event.pk), _update(message)))


def announce_submission(submission: Submission, *, ranked: bool = False) -> None:
    """A submission's status or score, for its event's pages; ``ranked`` when it changed the
    leaderboard."""
    message = {
        "type": "submission",
        "event": submission.event_id,
        "submission": submission.pk,
        "status": submission.status,
        "status_display": submission.get_status_display(),
        "score_ms": submission.score_ms,
        "qualified": submission.qualified,
        "ranked": ranked,
    }
    transaction.on_commit(lambda: live.send(event_group(submission.event_id), _update(message)))


def _update(message: dict) -> dict:
    return {"type": "event.update", "message": message}
