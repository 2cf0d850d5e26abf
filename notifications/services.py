"""Writes for notifications: telling a racer that something they started has ended, in the
console (the bell) and, where the site names an email server (``PITLANE_EMAIL_URL``), by email.

The event functions below are what the training and racing code call at the moment a training
job, an evaluation or a race ends; each says what happened in a racer's words and links to the
page that shows it. None of them raises for a failed email: the console keeps the notification.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable

from django.conf import settings
from django.contrib.auth.models import AbstractBaseUser
from django.core.mail import send_mail
from django.db import transaction
from django.urls import reverse
from django.utils import timezone

from common.formatting import clock, laptime
from notifications.models import Notification

logger = logging.getLogger(__name__)


def notification_send(*, recipient: AbstractBaseUser, text: str, url: str = "") -> Notification:
    """Tell ``recipient`` ``text``, linking to ``url`` (a path on this site): in the console,
    and by email once the transaction commits when email is configured and they have an
    address."""
    notification = Notification.objects.create(recipient=recipient, text=text[:500], url=url)
    if settings.PITLANE_EMAIL_NOTIFICATIONS and recipient.email:
        transaction.on_commit(lambda: _email(notification))
    return notification


def _email(notification: Notification) -> None:
    link = settings.PITLANE_SITE_URL.rstrip("/") + (notification.url or "/notifications/")
    try:
        send_mail(
            subject=f"Pitlane: {notification.text[:120]}",
            message=f"{notification.text}\n\n{link}\n\n"
            "You get this email because you race on Pitlane.",
            from_email=None,  # DEFAULT_FROM_EMAIL
            recipient_list=[notification.recipient.email],
        )
    except Exception:  # the console has it; a mail server's trouble is not the racer's
        logger.exception("Could not email notification %s", notification.pk)


def notifications_mark_read(*, recipient: AbstractBaseUser) -> int:
    """Mark every unread notification of ``recipient`` read; how many there were."""
    return Notification.objects.filter(recipient=recipient, read_at__isnull=True).update(
        read_at=timezone.now()
    )


def notification_mark_read(*, notification: Notification) -> None:
    if notification.read_at is None:
        notification.read_at = timezone.now()
        notification.save(update_fields=["read_at"])


# The moments the console tells a racer about. They run at the end of a trainer's, an
# evaluation's or a race's work: a notification that cannot be written is logged, and never
# changes how that work ended.


def _quietly(event: Callable[..., Notification | None]) -> Callable[..., Notification | None]:
    @functools.wraps(event)
    def told(**about) -> Notification | None:
        try:
            return event(**about)
        except Exception:
            logger.exception("Could not notify %s", event.__name__)
            return None

    return told


@_quietly
def training_ended(*, job) -> Notification | None:
    """A training job has completed (its time was up, or the racer stopped it) or failed."""
    model = job.model
    url = reverse("training:model-detail", args=[model.pk])
    done = f"{job.iterations} iteration{'s' if job.iterations != 1 else ''}"
    if job.status == job.Status.FAILED:
        text = f"{model.name}'s training failed after {clock(job.training_seconds)}: "
        text += job.failure_reason or "see its page."
    elif job.stop_requested or type(job).objects.filter(pk=job.pk, stop_requested=True).exists():
        text = f"{model.name} stopped training as you asked, after {done} in "
        text += f"{clock(job.training_seconds)}; it is ready to evaluate."
    else:
        text = f"{model.name} finished training: {done} in {clock(job.training_seconds)}; "
        text += "it is ready to evaluate."
    return notification_send(recipient=model.owner, text=text, url=url)


@_quietly
def evaluation_ended(*, evaluation) -> Notification | None:
    """An evaluation the racer started has ended; a race's evaluation says nothing (the race
    does, once it is scored)."""
    if hasattr(evaluation, "submission"):
        return None
    model = evaluation.model
    url = reverse("training:evaluation-detail", args=[model.pk, evaluation.pk])
    where = f"{model.name}'s evaluation on {evaluation.track}"
    if evaluation.status != evaluation.Status.COMPLETED:
        text = f"{where} failed: {evaluation.failure_reason or 'see its page.'}"
    else:
        done, trials = evaluation.completed_trials, evaluation.trials
        laps = f"{done} of {trials} lap{'s' if trials != 1 else ''} completed"
        best = evaluation.best_lap_ms
        text = f"{where} is done: {laps}" + (f", best lap {laptime(best)}." if best else ".")
    return notification_send(recipient=model.owner, text=text, url=url)


@_quietly
def submission_scored(*, submission) -> Notification | None:
    """A race submission has been driven and scored."""
    where = f"{submission.model_name} in {submission.event.name}"
    count = submission.laps_completed
    laps = f"{count} lap{'s' if count != 1 else ''} completed"
    if submission.qualified and submission.score_ms is not None:
        text = f"{where} is scored: {laptime(submission.score_ms)}, {laps}."
    else:
        text = f"{where} is scored: it did not qualify ({laps})."
    return notification_send(
        recipient=submission.racer, text=text, url=submission.get_absolute_url()
    )


@_quietly
def live_turn_next(*, entry) -> Notification | None:
    """A racer in a live race's queue is next: their turn starts when the one driving ends."""
    event = entry.session.event
    text = f"You are next in {event.name}'s live race: {entry.model_name} drives when the turn "
    text += "on the track ends."
    return notification_send(
        recipient=entry.racer, text=text, url=reverse("racing:live-race", args=[event.slug])
    )


@_quietly
def submission_disqualified(*, submission) -> Notification | None:
    """League staff disqualified a race submission: the racer is told why."""
    text = (
        f"{submission.model_name} in {submission.event.name} was disqualified by the league "
        f"staff: {submission.disqualification_reason or 'no reason given.'}"
    )
    if not text.endswith((".", "!", "?")):
        text += "."
    text += " It no longer counts on the leaderboard."
    return notification_send(
        recipient=submission.racer, text=text, url=submission.get_absolute_url()
    )
