"""Summaries made as traces are recorded (``training.signals.trace_recorded``)."""

from __future__ import annotations

import logging

from analysis import records

logger = logging.getLogger(__name__)


def summarize_recorded(
    sender, *, document: str, job=None, iteration: int = 0, evaluation=None, **kwargs
) -> None:
    """Summarise a trace as it is recorded. A summary that cannot be made is logged and made
    again when a page asks for it: it never stops the training or the evaluation."""
    try:
        records.summarize_document(document, job=job, iteration=iteration, evaluation=evaluation)
    except Exception:
        logger.exception("Could not summarise the trace of %s", job or evaluation)
