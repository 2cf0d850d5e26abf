"""A status field's lifecycle: the moves its values may make, and the only way to write it.

After a row is created (in one of its ``born`` statuses), every write of its status is a
``move``, which makes only the moves its table lists. A move is one conditional UPDATE (the
status changes only from a value it may change from), so two writers racing cannot take a row
where neither meant. Each app lists its own tables (``training.lifecycle``,
``racing.services.SUBMISSION``, ``racing.live_races.LIVE_ENTRY``).
"""

from __future__ import annotations

from collections.abc import Mapping

from django.db import models
from django.utils import timezone


class Lifecycle:
    """The moves a status field may make: ``moves`` maps each status to where it may go,
    ``born`` lists those a row may be created with."""

    def __init__(
        self, model: type[models.Model], moves: Mapping[str, frozenset[str]], born: frozenset[str]
    ) -> None:
        self.model = model
        self.moves = dict(moves)
        self.born = born
        self._touch = any(field.name == "updated_at" for field in model._meta.fields)

    def sources(self, to: str) -> frozenset[str]:
        """The statuses a row may move to ``to`` from (``to`` itself: a move that was made)."""
        return frozenset({origin for origin, ends in self.moves.items() if to in ends} | {to})

    def move(
        self,
        row: models.Model | int,
        to: str,
        *,
        only_from: frozenset[str] | None = None,
        within: models.QuerySet | None = None,
        **fields,
    ) -> bool:
        """Move the row to ``to``, writing ``fields`` with it, if its status now allows it (and
        is one of ``only_from``, when given: ``to`` itself then only if listed) and it is one of
        ``within`` (a job's rows while a run holds its lease, say); whether it moved (or was at
        ``to`` already). The instance given, if any, follows."""
        allowed = self.sources(to) if only_from is None else self.sources(to) & only_from
        pk = row if isinstance(row, int) else row.pk
        rows = (self.model.objects.all() if within is None else within).filter(pk=pk)
        changes = {**fields, "status": to}
        if self._touch:
            changes["updated_at"] = timezone.now()
        moved = rows.filter(status__in=allowed).update(**changes) > 0
        if moved and not isinstance(row, int):
            for name, value in changes.items():
                setattr(row, name, value)
        return moved
