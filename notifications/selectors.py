"""Reads for notifications."""

from __future__ import annotations

from django.contrib.auth.models import AbstractBaseUser
from django.db.models import QuerySet

from notifications.models import Notification

PAGE = 100  # the newest a racer's list shows


def notifications_for(*, recipient: AbstractBaseUser) -> QuerySet[Notification]:
    return Notification.objects.filter(recipient=recipient)[:PAGE]


def unread_count(*, recipient: AbstractBaseUser) -> int:
    """The bell's number: one indexed count."""
    return Notification.objects.filter(recipient=recipient, read_at__isnull=True).count()
