"""What staff see on System, for their scripts and monitors: the health of what the console
depends on (``common.health``, as /healthz reports it), the Celery workers, and the training
queue with each job's place. Staff only, with the ``admin`` scope."""

from __future__ import annotations

from datetime import datetime

from django.conf import settings
from ninja import Router, Schema

from accounts.models import TokenScope
from accounts.selectors import racer_name
from api.auth import need
from api.racer_models import TrainingStatus
from api.schemas import REFUSED
from common.health import system_health
from training import leases, selectors
from training.models import TrainingJob

router = Router()
UNDER_WAY = (
    TrainingJob.Status.QUEUED,
    TrainingJob.Status.INITIALIZING,
    TrainingJob.Status.IN_PROGRESS,
)


class QueuedJob(Schema):
    job: int
    model: int
    model_name: str
    racer: str
    status: TrainingStatus
    queue_position: int | None
    queue_words: str
    workers: int
    created_at: datetime


class SystemOut(Schema):
    status: str  # "ok" or "down"
    down: list[str]
    checks: dict
    trainers: int
    trainers_free: int
    queue: list[QueuedJob]


@router.get("", response={200: SystemOut, **REFUSED})
def system(request):
    """The console's health (database, Redis, the workers and their sandboxes' self-tests), and
    every training under way or waiting, in the queue's order."""
    need(request, TokenScope.ADMIN)
    free = leases.trainers_free()
    jobs = (
        TrainingJob.objects.filter(status__in=UNDER_WAY)
        .select_related("model__owner__profile")
        .order_by("created_at", "pk")
    )
    return {
        **system_health(),
        "trainers": settings.PITLANE_TRAINERS,
        "trainers_free": free,
        "queue": [
            {
                "job": job.pk,
                "model": job.model_id,
                "model_name": job.model.name,
                "racer": racer_name(racer=job.model.owner),
                "status": job.status,
                "queue_position": leases.queue_position(job),
                "queue_words": selectors.queue_words(job=job, free=free),
                "workers": job.model.workers,
                "created_at": job.created_at,
            }
            for job in jobs
        ],
    }
