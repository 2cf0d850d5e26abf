"""The statuses of a re-scoring and the moves between them (``training.lifecycle``'s rule: every
write of a status is a move, one conditional UPDATE)."""

from __future__ import annotations

from analysis.models import Rescoring
from common.lifecycle import Lifecycle

_R = Rescoring.Status
RESCORING = Lifecycle(
    Rescoring,
    {
        # A worker takes it up, or it fails before (its source was deleted).
        _R.QUEUED: frozenset({_R.RUNNING, _R.FAILED}),
        _R.RUNNING: frozenset({_R.DONE, _R.FAILED}),
        _R.DONE: frozenset(),
        _R.FAILED: frozenset(),
    },
    born=frozenset({_R.QUEUED}),
)
