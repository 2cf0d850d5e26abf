"""Slow work stays outside write transactions.

With SQLite, a transaction takes the database's one write lock when it begins (IMMEDIATE), so
any slow step run inside one (a sandbox run, a route file's check, a file written to storage)
makes every other writer wait: racers' pages answer 503 and trainers die on "database is
locked". The known slow steps call ``outside_transaction`` first; the test settings make it
raise, so a test that walks such a path inside a transaction fails, and elsewhere it logs.
"""

from __future__ import annotations

import logging

from django.conf import settings
from django.db import connection

logger = logging.getLogger(__name__)


class SlowStepInTransaction(RuntimeError):
    """A slow step was run while a write transaction was open."""


def outside_transaction(step: str) -> None:
    """Say (raise under ``PITLANE_TRANSACTION_GUARD``, log otherwise) that ``step``, slow work,
    was called while a transaction is open on the default database."""
    if not in_transaction():
        return
    message = f"{step} ran inside a database transaction, holding other writers back"
    if getattr(settings, "PITLANE_TRANSACTION_GUARD", False):
        raise SlowStepInTransaction(message)
    logger.error(message)


def in_transaction() -> bool:
    """Whether the code has a transaction open on the default database (a test's own wrapping
    transaction, pytest-django's or Django's TestCase's, is not the code's)."""
    return any(not block._from_testcase for block in connection.atomic_blocks)
