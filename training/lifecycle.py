"""A model's status and the moves between its values: after a model is created, every write of
``RLModel.status`` is a ``move`` here, which makes only the moves ``MOVES`` lists.

A move is one conditional UPDATE (the status changes only from a value it may change from), so two
writers racing cannot take a model where neither meant: a racer's stop that lands while the
trainer starts leaves the model STOPPING, not TRAINING; an evaluation that ends after the model
was deleted writes nothing.
"""

from __future__ import annotations

from django.utils import timezone

from training.models import RLModel

Status = RLModel.Status

# Where a model may go from each status, and why.
MOVES: dict[str, frozenset[str]] = {
    # The trainer takes it up; the racer stops it before or while it starts; the trainer ends it.
    Status.QUEUED: frozenset({Status.TRAINING, Status.STOPPING, Status.READY, Status.ERROR}),
    # The racer stops it; the trainer ends it (READY with a checkpoint, ERROR without).
    Status.TRAINING: frozenset({Status.STOPPING, Status.READY, Status.ERROR}),
    Status.STOPPING: frozenset({Status.READY, Status.ERROR}),
    # An evaluation or a race entry drives it; the racer deletes it.
    Status.READY: frozenset({Status.EVALUATING, Status.SUBMITTING, Status.DELETING}),
    Status.ERROR: frozenset({Status.DELETING}),
    Status.EVALUATING: frozenset({Status.READY}),
    Status.SUBMITTING: frozenset({Status.READY}),
    # A delete whose storage failed part-way gives the model back as it was.
    Status.DELETING: frozenset({Status.READY, Status.ERROR}),
    Status.IMPORTING: frozenset({Status.READY, Status.ERROR}),
}
# Where a model's life begins: a new model queued for training, an import with its weights.
BORN = frozenset({Status.QUEUED, Status.READY})


def sources(to: str) -> frozenset[str]:
    """The statuses a model may move to ``to`` from (``to`` itself: a move that was made)."""
    return frozenset({origin for origin, targets in MOVES.items() if to in targets} | {to})


def move(model: RLModel | int, to: str, *, only_from: frozenset[str] | None = None) -> bool:
    """Move the model to ``to`` if its status now allows it (and is one of ``only_from``, when
    given: ``to`` itself then only if listed); whether it moved (or was at ``to`` already). The
    model instance given, if any, follows."""
    allowed = sources(to) if only_from is None else sources(to) & only_from
    pk = model if isinstance(model, int) else model.pk
    rows = RLModel.objects.filter(pk=pk, status__in=allowed)
    moved = rows.update(status=to, updated_at=timezone.now()) > 0
    if moved and isinstance(model, RLModel):
        model.status = to
    return moved
