"""Where a trainer's time goes: each iteration's wall time, split by phase.

Every moment of the trainer's loop is charged to one phase, so an iteration's phases add up to
its wall time, from the end of the previous iteration (or the start of training) to the end of
its own. The evaluation of a checkpoint drives beside the next iteration, on the first worker,
and is timed there (``Iteration.evaluation_seconds``), outside the split.
"""

from __future__ import annotations

import time

DRIVING, TRANSFER, UPDATE, SAVING, CHECKS = "driving", "transfer", "update", "saving", "checks"
PHASES = {
    # The trainer waits while the workers drive the iteration's episodes (and for the first
    # episode to arrive).
    DRIVING: "Driving",
    # The other episodes and the new weights through Redis, and the episodes' checks.
    TRANSFER: "Redis transfer",
    # The policy update (the optimiser's epochs over the iteration's episodes).
    UPDATE: "Policy update",
    # The checkpoint, the iteration's row, the metrics and the simulation trace.
    SAVING: "Saving",
    # The lease, the clock, the workers' heartbeats, the log and the evaluation results.
    CHECKS: "Checks",
}


class Stopwatch:
    """A split of the wall time: ``charge(phase)`` charges the time since the last charge to
    ``phase``, so the phases of a ``take`` add up to the time since the one before."""

    def __init__(self) -> None:
        self.mark = time.monotonic()
        self.spent = dict.fromkeys(PHASES, 0.0)

    def charge(self, phase: str) -> None:
        now = time.monotonic()
        self.spent[phase] += now - self.mark
        self.mark = now

    def take(self) -> dict[str, float]:
        """The time charged to each phase since the last take [s], to the millisecond."""
        spent, self.spent = self.spent, dict.fromkeys(PHASES, 0.0)
        return {phase: round(seconds, 3) for phase, seconds in spent.items()}
