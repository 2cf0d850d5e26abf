"""More training jobs than the console has trainers all train: trainers and simulations have pools
of their own (console.supervisor.worker_pools), so a trainer never holds a place its rollouts
need, and an extra job waits in the queue with its place shown (issue 42: three jobs took all
three worker processes as trainers, no rollout ever started, and all three failed)."""

import pytest
from django.urls import reverse

from tests.conftest import TRAINERS
from tests.helpers.training import reload
from tests.helpers.training import settings as model_settings
from tests.services import wait_for
from training import selectors
from training.models import TrainingJob
from training.services import model_create, training_stop


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.django_db(transaction=True)
def test_more_jobs_than_trainers_all_train_and_the_one_waiting_is_shown_its_place(
    client, alice, tracks, celery_worker_process
):
    models = [
        model_create(owner=alice, settings=model_settings(name=f"pool-{n}"), validate_reward=False)
        for n in range(TRAINERS + 1)
    ]
    started = [model.jobs.get() for model in models]

    def taken() -> list[TrainingJob]:
        return [job for job in map(reload, started) if job.status != TrainingJob.Status.QUEUED]

    wait_for(lambda: len(taken()) == TRAINERS, "the trainers to take a job each", timeout=120)
    (waiting,) = (job for job in map(reload, started) if job.status == TrainingJob.Status.QUEUED)
    status = selectors.training_status(job=waiting)
    assert (status["queue_position"], status["seconds_used"]) == (1, 0)
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[waiting.model_id])).text
    assert "Queued: number 1 in the queue, waiting for a free trainer" in page

    def each_stopped_once_it_has_an_iteration() -> bool:
        for job in map(reload, started):
            assert job.status != TrainingJob.Status.FAILED, job.failure_reason
            if job.iterations and not job.stop_requested:
                training_stop(job=job)  # frees its trainer for the job that waits
        return all(reload(job).stop_requested for job in started)

    wait_for(each_stopped_once_it_has_an_iteration, "every job to train", timeout=480)
    wait_for(
        lambda: all(not reload(job).is_active for job in started), "the jobs to end", timeout=60
    )
    ended = [reload(job) for job in started]
    assert [job.status for job in ended] == [TrainingJob.Status.COMPLETED] * len(ended)
    assert all(job.iterations >= 1 and job.training_seconds > 0 for job in ended)
