"""Celery tasks of training: adapters that load ids and call the trainer or a rollout worker.

The trainer and rollout modules (torch, the simulator) are imported when a task runs, so the web
process, which only enqueues, never loads them.
"""

from __future__ import annotations

import os

from celery import shared_task

LONGEST_JOB = 24 * 3600  # [s] the longest training time a racer may ask for
EVALUATION_LIMIT = 3600  # [s] five trials of at most 10,000 steps each, in real time at worst


@shared_task(
    name="training.train",
    bind=True,
    acks_late=True,
    ignore_result=True,
    soft_time_limit=LONGEST_JOB + 900,
    time_limit=LONGEST_JOB + 1200,
)
def train(self, job_id: int) -> None:
    from training import trainer

    torch_threads()
    owner = f"{self.request.hostname}:{os.getpid()}"
    if not trainer.run(job_id, owner=owner, start_rollouts=start_rollout):
        # Another run holds the job: a duplicate delivery, or a redelivery after that run's
        # worker died. Look again when its lease would have lapsed; never train twice.
        from django.conf import settings

        raise self.retry(countdown=settings.PITLANE_TRAINER_LEASE + 5, max_retries=None)


@shared_task(
    name="training.rollout",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=LONGEST_JOB + 900,
    time_limit=LONGEST_JOB + 1200,
)
def rollout(job_id: int, worker: int, attempt: int, track: str) -> None:
    from training import rollouts

    rollouts.run(job_id, worker, attempt, track)


@shared_task(
    name="training.evaluate",
    acks_late=True,
    ignore_result=True,
    soft_time_limit=EVALUATION_LIMIT,
    time_limit=EVALUATION_LIMIT + 60,
)
def evaluate(evaluation_id: int) -> None:
    from training import evaluation

    evaluation.run(evaluation_id)


def resume_lapsed() -> list[str]:
    """Send a trainer for each job whose run died (``jobs.lapsed_claim``), and a simulation
    worker for each evaluation or race whose run died (``jobs.lapsed_evaluations``); what was
    sent for, in words for the log. Every worker calls it every few seconds
    (``console.workers``), so the work goes on whichever machines are left."""
    from training import jobs, signals
    from training.models import EvaluationJob

    sent = []
    for job in jobs.lapsed_claim():
        train.delay(job.pk)
        sent.append(f"training job {job.pk} lost its trainer; another is sent for")
    for evaluation in jobs.lapsed_evaluations():
        answers = signals.evaluation_lapsed.send(EvaluationJob, evaluation=evaluation)
        if not any(answered for _, answered in answers):
            evaluate.delay(evaluation.pk)
        sent.append(f"evaluation {evaluation.pk} lost its simulation worker; it is driven again")
    return sent


def torch_threads() -> None:
    """The trainer's threads: every core by default, as it learns only while the rollout workers
    wait for its new weights; the setting keeps a share for a machine that runs more."""
    import torch
    from django.conf import settings

    torch.set_num_threads(settings.PITLANE_TRAINER_THREADS)


def start_rollout(job, slot) -> None:
    """Enqueue the rollout worker for ``slot`` of ``job`` (a ``trainer.Slot``)."""
    rollout.delay(job.pk, slot.index, job.attempt, slot.track)
