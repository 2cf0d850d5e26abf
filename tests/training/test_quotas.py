"""Quotas as on DeepRacer on AWS: models per racer and training minutes per month, set by staff
for each racer and for new ones; the wizard says what is left, and a model over it is refused."""

from datetime import timedelta

import pytest
from django.urls import reverse
from django.utils import timezone

from tests.helpers.models import ready_model
from tests.helpers.training import form_data
from training import configuration, leases, selectors
from training.models import Quota, QuotaDefaults, RLModel, TrainingJob
from training.services import model_create, training_stop

pytestmark = pytest.mark.django_db


def test_new_racers_get_the_defaults_staff_set(alice, bob):
    QuotaDefaults.objects.update_or_create(
        pk=1, defaults={"max_models": 3, "max_minutes_per_month": 90}
    )
    assert (Quota.of(alice).max_models, Quota.of(alice).max_minutes_per_month) == (3, 90)
    Quota.objects.filter(racer=bob).delete()
    Quota.objects.create(racer=bob, max_models=50, max_minutes_per_month=6000)  # staff's choice
    assert Quota.of(bob).max_models == 50


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_the_wizard_says_what_is_left_and_refuses_more_time(client, alice, tracks):
    Quota.objects.create(racer=alice, max_models=5, max_minutes_per_month=100)
    model = ready_model(alice)
    TrainingJob.objects.filter(model=model).update(training_seconds=30 * 60)  # 30 min used
    client.force_login(alice)
    page = client.get(reverse("training:model-create")).text
    assert "<strong>4</strong> of 5 models left" in page
    assert "<strong>70</strong> of 100 training minutes left this month" in page

    response = client.post(reverse("training:model-create"), form_data(max_minutes=80))
    assert response.status_code == 400
    assert "You have 70 training minutes left this month (of 100)" in response.text
    assert 'value="first-model"' in response.text  # what was typed stays
    response = client.post(reverse("training:model-create"), form_data(max_minutes=60))
    assert response.status_code == 302
    # The queued job holds its whole budget: 70 - 60 left.
    assert selectors.allowance_for(racer=alice).minutes_left == 10


def test_a_racer_at_the_model_limit_is_told_to_delete_one(client, alice, tracks):
    Quota.objects.create(racer=alice, max_models=1, max_minutes_per_month=600)
    ready_model(alice)
    client.force_login(alice)
    response = client.post(reverse("training:model-create"), form_data())
    assert response.status_code == 400
    assert "You have 1 models, your limit; delete one to make room." in response.text
    with pytest.raises(configuration.Invalid, match="your limit"):
        model_create(
            owner=alice,
            settings={
                "name": "other",
                "track": "rookie-loop",
                "reward_function": "def reward_function(params):\n    return 1.0\n",
            },
            validate_reward=False,
        )
    assert RLModel.objects.filter(owner=alice).count() == 1


def test_a_stopped_training_is_billed_the_time_up_to_the_stop_not_its_budget(alice, tracks):
    Quota.objects.create(racer=alice, max_models=5, max_minutes_per_month=100)
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(max_minutes=60, status=RLModel.Status.TRAINING)
    job = TrainingJob.objects.get(model=model)
    TrainingJob.objects.filter(pk=job.pk).update(
        status=TrainingJob.Status.IN_PROGRESS,
        attempt=1,
        lease_owner="trainer:1",
        training_seconds=5 * 60,
        clock_at=timezone.now() - timedelta(seconds=4),
    )
    assert selectors.allowance_for(racer=alice).minutes_left == 40  # it holds its 60 min

    stopped = training_stop(job=job)
    assert selectors.allowance_for(racer=alice).minutes_left == 94  # 5:04 used, while it saves

    # The iteration it was learning ends minutes later; the trainer's time does not count.
    assert leases.clock_write(stopped, 8 * 60 + 7) is False
    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED)
    assert selectors.allowance_for(racer=alice).minutes == pytest.approx(
        stopped.training_seconds / 60
    )
    assert selectors.allowance_for(racer=alice).minutes_left == 94


def test_time_past_the_limit_is_not_billed(alice, tracks):
    Quota.objects.create(racer=alice, max_models=5, max_minutes_per_month=100)
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(max_minutes=10)
    TrainingJob.objects.filter(model=model).update(training_seconds=10 * 60 + 42)
    assert selectors.allowance_for(racer=alice).minutes == 10
