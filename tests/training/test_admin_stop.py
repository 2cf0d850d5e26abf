"""The admin's "Stop training" says what happened to each model it was asked to stop."""

import pytest
from django.contrib.auth.models import User
from django.urls import reverse

from tests.helpers.models import ready_model
from training import admin
from training.models import RLModel, TrainingJob
from training.services import training_stop

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def test_the_admin_stops_a_training_model_and_says_a_ready_one_had_nothing_to_stop(client, alice):
    ready = ready_model(alice, "already-done")
    training = ready_model(alice, "still-learning")
    RLModel.objects.filter(pk=training.pk).update(status=RLModel.Status.TRAINING)
    TrainingJob.objects.filter(model=training).update(
        status=TrainingJob.Status.IN_PROGRESS, attempt=1, lease_owner="worker", iterations=1
    )
    client.force_login(User.objects.create_superuser("admin", password="pw-for-admin-123"))
    response = client.post(
        reverse("admin:training_rlmodel_changelist"),
        {"action": "stop_training", "_selected_action": [ready.pk, training.pk]},
        follow=True,
    )
    said = [str(message) for message in response.context["messages"]]
    assert "already-done: already ready: nothing to stop." in said
    assert "still-learning: stopping: saving the model from iteration 1." in said
    assert not any(text.startswith("already-done: stopping") for text in said)
    assert RLModel.objects.get(pk=ready.pk).status == RLModel.Status.READY
    assert RLModel.objects.get(pk=training.pk).status == RLModel.Status.STOPPING


def test_a_training_that_ended_before_the_stop_is_said_as_it_stands_not_stopping(
    client, alice, monkeypatch
):
    model = ready_model(alice, "just-finished")
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.TRAINING)
    TrainingJob.objects.filter(model=model).update(
        status=TrainingJob.Status.IN_PROGRESS, attempt=1, lease_owner="worker", message=""
    )

    def finished_meanwhile(*, job):
        TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED)
        RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.READY)
        return training_stop(job=job)

    monkeypatch.setattr(admin, "training_stop", finished_meanwhile)
    client.force_login(User.objects.create_superuser("admin", password="pw-for-admin-123"))
    response = client.post(
        reverse("admin:training_rlmodel_changelist"),
        {"action": "stop_training", "_selected_action": [model.pk]},
        follow=True,
    )
    said = [str(message) for message in response.context["messages"]]
    assert said == ["just-finished: already ready: nothing to stop."]
