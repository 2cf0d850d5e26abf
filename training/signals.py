"""What training tells the apps above it, without importing them."""

from django.dispatch import Signal

# A simulation trace was recorded: ``document`` (its CSV) with ``job`` and ``iteration`` (1, 2,
# ...) for a training iteration, or with ``evaluation`` for an evaluation or a race entry.
trace_recorded = Signal()
