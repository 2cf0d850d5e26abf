"""What training tells the apps above it, without importing them."""

from django.dispatch import Signal

# A simulation trace was recorded: ``document`` (its CSV) with ``job`` and ``iteration`` (1, 2,
# ...) for a training iteration, or with ``evaluation`` for an evaluation or a race entry.
trace_recorded = Signal()

# An evaluation whose run died was claimed to be driven again (``leases.lapsed_evaluations``): a
# receiver that sends the task that drives it (a race entry's) returns True; when none does, the
# evaluation's own task is sent.
evaluation_lapsed = Signal()

# Which queued evaluations have their task waiting in the broker (``console.recovery.resend_lost``):
# ``waiting`` maps a task's name to the first arguments of its messages; a receiver whose own
# task drives evaluations (a race entry's) returns the ids of the evaluations it waits to drive.
evaluations_waiting = Signal()
