"""The recovery sweeps every worker's heartbeat runs (``console.workers``): work whose worker
died is sent for again, and what died half-done is cleared away.

Any worker may run them: whichever looks first claims each item (``training.leases``), so it is
sent for once, and the work goes on whichever machines are left.
"""

from __future__ import annotations

from archives import imports, kept_uploads
from jobs.tasks import evaluate, train, waiting
from training import leases, signals
from training.models import EvaluationJob


def resume_lapsed() -> list[str]:
    """Send a trainer for each job whose run died (``leases.lapsed_claim``), and a simulation
    worker for each evaluation or race whose run died (``leases.lapsed_evaluations``); what was
    sent for, in words for the log; then what lost its task while queued (``resend_lost``),
    and the imports that died storing their files (``imports.abandoned_imports_remove``), and
    the uploads kept for an import that expired (``kept_uploads.uploads_expire``).
    Every worker calls it every few seconds (``console.workers``)."""
    sent = []
    for job in leases.lapsed_claim():
        train.delay(job.pk)
        sent.append(f"training job {job.pk} lost its trainer; another is sent for")
    for evaluation in leases.lapsed_evaluations():
        _evaluation_send(evaluation)
        sent.append(f"evaluation {evaluation.pk} lost its simulation worker; it is driven again")
    removed = imports.abandoned_imports_remove() + kept_uploads.uploads_expire()
    return sent + resend_lost() + removed


def resend_lost() -> list[str]:
    """Send again the task of each queued job and evaluation whose task is gone: not in the
    broker (``waiting``) for ``leases.LOST_AFTER`` (``leases.lost_queued_claim``); what was sent,
    in words for the log. A trainer delivered twice never trains twice (the lease), nor is an
    evaluation driven twice, so a task sent again that turns up after all does nothing."""
    found = waiting()
    if found is None:
        return []
    sent = []
    for job in leases.lost_queued_claim(waiting=found.get(train.name, set())):
        train.delay(job.pk)
        sent.append(f"queued training job {job.pk} had lost its task; it is sent again")
    evaluations = set(found.get(evaluate.name, set()))
    for _, theirs in signals.evaluations_waiting.send(EvaluationJob, waiting=found):
        evaluations |= set(theirs)
    for evaluation in leases.lost_queued_evaluations(waiting=evaluations):
        _evaluation_send(evaluation)
        sent.append(f"queued evaluation {evaluation.pk} had lost its task; it is sent again")
    return sent


def _evaluation_send(evaluation) -> None:
    """Send the task that drives ``evaluation``: a receiver of ``evaluation_lapsed`` sends its
    own (a race entry's race task), else ``evaluate``."""
    answers = signals.evaluation_lapsed.send(EvaluationJob, evaluation=evaluation)
    if not any(answered for _, answered in answers):
        evaluate.delay(evaluation.pk)
