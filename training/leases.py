"""A training job's lease: one trainer run at a time, and only the current one may write.

A trainer run takes the lease by raising the job's attempt counter, and renews it while it works;
every write it makes is conditional on that attempt. A second delivery of the same task finds the
lease held and returns; a run whose worker died leaves the lease to expire, and the next delivery
takes the job over with a higher attempt (and resumes from its last checkpoint), after which the
old run, were it still alive, can no longer write. That delivery is sent for by whichever worker
looks first (``lapsed_claim``, from every worker's heartbeat), so a job whose training machine
died goes on on another, rather than when the broker would hand its task out again.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Iterator
from datetime import timedelta

from django.conf import settings
from django.db import DatabaseError, connection, transaction
from django.db.models import QuerySet
from django.utils import timezone

from training import lifecycle
from training.models import EvaluationJob, JobLogLine, TrainingJob

logger = logging.getLogger(__name__)
IMPORTED = "import"  # the lease owner of a job an import recorded: it never ran on this console
RESUMING = "resuming"  # the lease owner of a job whose run died, while another is sent for
LAPSED = (
    "The trainer stopped answering (its machine may have stopped); another training worker takes "
    "the job up from its last checkpoint."
)


EVALUATION_LAPSED = (
    "The simulation machine driving it stopped answering; another one drives the evaluation "
    "again from the start."
)


LOST_AFTER = 30  # [s] a queued job or evaluation whose task is not in the broker this long lost it
QUEUED_LOST = (
    "Its place in the queue was lost (the console's queue restarted, or a worker stopped as it "
    "took the job); it was sent again, keeping its place."
)


EVALUATION_STOPPED = "Stopped by you; the trials it finished are kept, with their video and trace."
EVALUATION_STOPPED_UNSAVED = (
    "Stopped by you; the simulation machine driving it stopped answering as it stopped, before "
    "it saved the video and trace: the trials it finished are kept, without them."
)
EVALUATION_STOP_LOOK = 0.5  # [s] between a driving evaluation's looks for the racer's stop


class LeaseLost(Exception):
    """Another run holds the job now; this one must stop without writing."""


def lease_acquire(*, job_id: int, owner: str) -> TrainingJob | None:
    """The job with its lease taken by ``owner`` (attempt raised), or None when the job has ended,
    vanished, or another run holds a live lease."""
    now = timezone.now()
    with transaction.atomic():
        job = (
            TrainingJob.objects.select_for_update()
            .select_related("model")
            .filter(pk=job_id)
            .first()
        )
        if job is None or not job.is_active:
            return None
        held = job.lease_owner not in ("", RESUMING)
        if held and job.lease_expires and job.lease_expires > now:
            return None
        job.attempt += 1
        job.lease_owner = owner
        job.lease_expires = now + lease()
        job.save(update_fields=["attempt", "lease_owner", "lease_expires"])
    return job


def lease() -> timedelta:
    """How long a run's lease lasts unrenewed (``PITLANE_TRAINER_LEASE``)."""
    return timedelta(seconds=settings.PITLANE_TRAINER_LEASE)


@contextlib.contextmanager
def lease_renewed(job: TrainingJob) -> Iterator[None]:
    """While the block runs, renew ``job``'s lease (while its attempt holds it: a trainer's, or
    a new clone's held send) every third of a lease, from a thread: slow file work (a clone's
    weights copied to a bucket) may outlast a lease, and the job must not be taken for lost
    meanwhile; a holder that dies stops renewing, and the lease lapses as it would."""
    rows = _held(job)
    done = threading.Event()

    def renew() -> None:
        try:
            while not done.wait(lease().total_seconds() / 3):
                rows.update(lease_expires=timezone.now() + lease())
        except DatabaseError as error:
            logger.warning("A job's lease could not be renewed: %s", error)
        finally:
            connection.close()

    renewing = threading.Thread(target=renew, name="lease-renewal", daemon=True)
    renewing.start()
    try:
        yield
    finally:
        done.set()
        renewing.join()


def lapsed_claim() -> list[TrainingJob]:
    """The jobs whose run died (its lease lapsed while the job was under way), each claimed for
    one new run: the caller enqueues a ``training.train`` task for each. A job is claimed once
    per lapse (by one caller, whichever worker looks first), and again a lease later if no run
    has taken it up by then (the task was lost with a Redis restart, say)."""
    now = timezone.now()
    lapsed = TrainingJob.objects.filter(
        status__in=TrainingJob.ACTIVE, attempt__gt=0, lease_expires__lt=now
    ).exclude(lease_owner__in=("", IMPORTED))
    claimed = []
    for job in lapsed:
        rows = TrainingJob.objects.filter(
            pk=job.pk, attempt=job.attempt, lease_owner=job.lease_owner, lease_expires__lt=now
        )
        if rows.update(lease_owner=RESUMING, lease_expires=now + lease()):
            if job.lease_owner != RESUMING:
                log(job, LAPSED, "warning")
            claimed.append(job)
    return claimed


def lapsed_evaluations() -> list[EvaluationJob]:
    """The evaluations (race entries' too) whose run died while driving, each claimed once per
    lapse, as ``lapsed_claim`` claims jobs: the caller sends each to be driven again (one the
    racer was stopping is ended by that run, with what it had)."""
    now = timezone.now()
    statuses = EvaluationJob.Status
    lapsed = EvaluationJob.objects.filter(
        status__in=(statuses.INITIALIZING, statuses.IN_PROGRESS, statuses.STOPPING),
        lease_expires__lt=now,
        grid_leader__isnull=True,  # a race's first car's run drives all
    ).exclude(lease_owner="")
    claimed = []
    for evaluation in lapsed:
        rows = EvaluationJob.objects.filter(
            pk=evaluation.pk, lease_owner=evaluation.lease_owner, lease_expires__lt=now
        )
        fields = {"lease_owner": RESUMING, "lease_expires": now + lease()}
        if evaluation.lease_owner != RESUMING:
            fields["message"] = EVALUATION_LAPSED
        if rows.update(**fields):
            claimed.append(evaluation)
    return claimed


def lost_queued_claim(*, waiting: set[int]) -> list[TrainingJob]:
    """The queued jobs that no trainer has taken and whose task is gone (not among ``waiting``,
    the jobs whose ``training.train`` is in the broker; lost when sending it failed, with a
    Redis restart, with a worker that died holding it, or when its trainer failed before taking
    the lease), each claimed for one new send, as ``lapsed_claim`` claims jobs: once, and again
    a lease later if no trainer has taken it by then. Its queue position, by when it was
    created, stays the same."""
    now = timezone.now()
    claimed = []
    for job in _unclaimed(TrainingJob.objects.filter(attempt=0), waiting, now):
        if _claim(TrainingJob.objects.filter(pk=job.pk, attempt=0), job, now):
            if job.lease_owner != RESUMING:
                log(job, QUEUED_LOST, "warning")
            claimed.append(job)
    return claimed


def lost_queued_evaluations(*, waiting: set[int]) -> list[EvaluationJob]:
    """The queued evaluations (race entries' too) whose task is gone (not among ``waiting``),
    each claimed for one new send as ``lost_queued_claim`` claims jobs."""
    now = timezone.now()
    # the other cars of a race have no task: their race's first car's drives them
    lost = _unclaimed(EvaluationJob.objects.filter(grid_leader__isnull=True), waiting, now)
    return [e for e in lost if _claim(EvaluationJob.objects.filter(pk=e.pk), e, now)]


def _unclaimed(rows, waiting: set[int], now) -> list:
    """Of ``rows``, those QUEUED for ``LOST_AFTER`` whose task is not ``waiting`` and that no one
    has claimed (or whose claim lapsed, nothing having taken them since)."""
    queued = rows.filter(status="QUEUED", created_at__lt=now - timedelta(seconds=LOST_AFTER))
    unclaimed = queued.filter(lease_owner="") | queued.filter(
        lease_owner=RESUMING, lease_expires__lt=now
    )
    return [row for row in unclaimed if row.pk not in waiting]


def _claim(rows, row, now) -> bool:
    """Claim ``row`` (QUEUED, unchanged since it was read) for one new send, by one caller."""
    unchanged = rows.filter(status="QUEUED", lease_owner=row.lease_owner)
    if row.lease_owner:
        unchanged = unchanged.filter(lease_expires__lt=now)
    return bool(unchanged.update(lease_owner=RESUMING, lease_expires=now + lease()))


def _held(job: TrainingJob):
    """The job's row while ``job``'s attempt holds the lease (else no row)."""
    return TrainingJob.objects.filter(pk=job.pk, attempt=job.attempt, lease_owner=job.lease_owner)


def _mirror(job: TrainingJob, fields: dict) -> None:
    for name, value in fields.items():
        setattr(job, name, value)


def write(job: TrainingJob, **fields) -> None:
    """Update the job's row, only while ``job``'s attempt holds the lease; mirror on ``job``.
    Its status changes by ``move`` alone."""
    if "status" in fields:
        raise ValueError("A job's status changes by leases.move, as training.lifecycle allows.")
    if _held(job).update(**fields) != 1:
        raise LeaseLost(f"training job {job.pk} is held by another run")
    _mirror(job, fields)


def move(job: TrainingJob, to: str, **fields) -> bool:
    """Move the job to status ``to`` with ``fields`` as ``lifecycle.TRAINING_JOB`` allows, only
    while ``job``'s attempt holds the lease; whether it moved (False: its status, which ``job``
    then mirrors, does not allow it). ``LeaseLost`` when another run holds the job."""
    held = _held(job)
    if lifecycle.TRAINING_JOB.move(job, to, within=held, **fields):
        return True
    now = held.values("status", "stop_requested").first()
    if now is None:
        raise LeaseLost(f"training job {job.pk} is held by another run")
    _mirror(job, now)
    return False


def clock_write(job: TrainingJob, seconds: float, to: str | None = None, **fields) -> bool:
    """Write the training time used, measured now (``clock_at``), with ``fields`` (and the
    status ``to``, if lifecycle allows it), unless the racer has asked to stop: the stop froze
    the clock at the time it was asked (what is billed), and the trainer's later measurements
    must not move it. False when the stop was asked (``job`` then mirrors the frozen clock);
    ``LeaseLost`` when another run holds the job."""
    held = _held(job).filter(stop_requested=False)
    fields = {**fields, "training_seconds": seconds, "clock_at": timezone.now()}
    if to is None and held.update(**fields):
        _mirror(job, fields)
        return True
    if to is not None and lifecycle.TRAINING_JOB.move(job, to, within=held, **fields):
        return True
    frozen = _held(job).values("status", "training_seconds", "clock_at", "stop_requested").first()
    if frozen is None:
        raise LeaseLost(f"training job {job.pk} is held by another run")
    _mirror(job, frozen)
    return False


def saving_message(iterations: int) -> str:
    """What a stopping job waits for, in the racer's words."""
    if iterations:
        return f"Saving the model from iteration {iterations}"
    return "Saving the model as it started: no iteration finished"


def log(
    job: TrainingJob, text: str, level: str = "info", source: str = JobLogLine.Source.TRAINER
) -> None:
    JobLogLine.objects.create(job=job, text=text[:500], level=level, source=source)


def jobs_holding_trainers() -> QuerySet[TrainingJob]:
    """The jobs past the queue and not yet ended: each holds a trainer."""
    return TrainingJob.objects.filter(status__in=TrainingJob.ACTIVE).exclude(
        status=TrainingJob.Status.QUEUED
    )


def machine_shares(jobs: QuerySet[TrainingJob]) -> dict[int, int]:
    """``jobs``' shares of the machine, by job: their racers' (``Quota.machine_share``), 1 for a
    racer without a quota row yet."""
    rows = jobs.values_list("pk", "model__owner__quota__machine_share")
    return {pk: share or 1 for pk, share in rows}


def trainers_free() -> int:
    """Trainers (``PITLANE_TRAINERS``) that hold no job."""
    return max(settings.PITLANE_TRAINERS - jobs_holding_trainers().count(), 0)


def queue_position(job: TrainingJob) -> int | None:
    """1 for the next job to start; None when the job is not waiting."""
    if job.status != TrainingJob.Status.QUEUED:
        return None
    return (
        TrainingJob.objects.filter(
            status=TrainingJob.Status.QUEUED, created_at__lt=job.created_at
        ).count()
        + 1
    )
