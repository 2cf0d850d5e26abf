"""A model's page says only what is so now (issue 54): a queued job with a trainer free is
starting, not waiting; the words of a running job (the "Stopping" message, the evaluation still
to come) go once it has ended; the iteration table's best lap says it is a training lap; and a
job that trains beside others says how many it shares the machine with (issue 56)."""

import pytest
from django.urls import reverse

from tests.helpers.training import queued_job, training_job
from training import selectors
from training.models import Iteration, Quota, RLModel, TrainingJob

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]
EVALUATION_TO_COME = "Its evaluation drives beside the next iteration."


def page_of(client, racer, model: RLModel) -> str:
    client.force_login(racer)
    return client.get(reverse("training:model-detail", args=[model.pk])).text


def iteration(job: TrainingJob, number: int = 1) -> Iteration:
    """An iteration whose evaluation has not come in."""
    return Iteration.objects.create(
        job=job,
        number=number,
        reward=12.5,
        completion=40.0,
        best_lap_time=21.5,
        episodes=5,
        steps=500,
        wall_seconds=30.0,
        time_split={"driving": 20.0, "update": 10.0},
    )


def test_it_says_a_queued_job_is_starting_while_a_trainer_is_free(client, alice, settings):
    settings.PITLANE_TRAINERS = 1
    job = queued_job(alice)
    assert selectors.training_status(job=job)["queue_words"] == "starting on a free trainer"
    page = page_of(client, alice, job.model)
    assert "Queued: starting on a free trainer" in page
    assert "waiting for a free trainer" not in page

    training_job(alice, seconds=60, ago=1)  # holds the one trainer
    assert "Queued: number 1 in the queue, waiting for a free trainer" in page_of(
        client, alice, job.model
    )
    assert selectors.training_status(job=job)["queue_position"] == 1


def test_it_leaves_out_the_stopping_message_once_the_training_has_ended(client, alice, bob):
    job = training_job(alice, seconds=60, ago=1)
    client.force_login(alice)
    stop = reverse("training:model-stop", args=[job.model_id])
    page = client.post(stop, follow=True).text
    assert "data-live-when-active>Stopping: saving" in page  # hidden by the page at the end

    again = training_job(bob, seconds=60, ago=1)
    client.force_login(bob)
    response = client.post(reverse("training:model-stop", args=[again.model_id]))
    TrainingJob.objects.filter(pk=again.pk).update(status=TrainingJob.Status.COMPLETED)
    assert "Stopping: saving" not in client.get(response["Location"]).text


def test_it_says_no_evaluation_comes_once_the_training_has_ended(client, alice):
    job = training_job(alice, seconds=60, ago=1)
    iteration(job)
    assert EVALUATION_TO_COME in page_of(client, alice, job.model)

    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED)
    page = page_of(client, alice, job.model)
    assert EVALUATION_TO_COME not in page
    assert "Training ended before its evaluation finished." in page


def test_it_names_the_iteration_tables_best_lap_a_training_lap(client, alice):
    job = training_job(alice, seconds=60, ago=1)
    iteration(job)
    page = page_of(client, alice, job.model)
    assert '<th class="num">Best training lap</th>' in page
    assert "0:21.500" in page


def test_it_says_a_training_shares_the_machine_with_the_others_running(client, alice, bob):
    job = training_job(alice, seconds=60, ago=1)
    assert "sharing the machine" not in page_of(client, alice, job.model)  # it trains alone

    training_job(bob, seconds=60, ago=1)
    started = queued_job(bob)
    TrainingJob.objects.filter(pk=started.pk).update(status=TrainingJob.Status.INITIALIZING)
    queued_job(alice)  # waits for a trainer: it shares nothing yet
    words = "sharing the machine with 2 other trainings, each taking an equal share"
    assert f"In progress: {words}" in page_of(client, alice, job.model)
    assert selectors.training_status(job=job)["queue_words"] == words

    # Staff give alice twice everyone's share: her page says what she takes of the machine
    Quota.objects.filter(pk=Quota.of(alice).pk).update(machine_share=2)
    words = "sharing the machine with 2 other trainings, taking 2 of 4 shares"
    assert f"In progress: {words}" in page_of(client, alice, job.model)

    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED)
    assert "sharing the machine" not in page_of(client, alice, job.model)
