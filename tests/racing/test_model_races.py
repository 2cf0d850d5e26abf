"""A model's page lists its race submissions apart from the evaluations its racer ran."""

import pytest
from django.urls import reverse

from racing.models import Submission
from tests.helpers.league import event, race_evaluation
from tests.helpers.models import ready_model
from training import signals
from training.models import EvaluationJob, Track

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def test_race_submissions_are_listed_as_races_not_as_evaluations(client, alice):
    model = ready_model(alice)
    mine = EvaluationJob.objects.create(
        model=model, track=Track.objects.get(name="kidney-bean"), trials=5
    )
    cup = event("July cup")
    raced = Submission.objects.create(
        event=cup,
        racer=alice,
        model=model,
        model_name=model.name,
        evaluation=race_evaluation(model, cup),
        status=Submission.Status.COMPLETED,
        laps_completed=3,
        score_ms=31_234,
        qualified=True,
    )

    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[model.pk]))
    assert list(page.context["evaluations"]) == [mine]
    assert list(page.context["races"]) == [raced]
    races = page.text[page.text.index("data-model-races") :]
    assert "July cup" in races and "0:31.234" in races and "Qualified" in races
    assert raced.get_absolute_url() in races
    evaluations = page.text[
        page.text.index("<h2>Evaluations</h2>") : page.text.index("data-model-races")
    ]
    assert "5 trials" in evaluations and "3 trials" not in evaluations


def test_a_model_that_never_raced_shows_no_races_section(client, alice):
    model = ready_model(alice)
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[model.pk]))
    assert "data-model-races" not in page.text


def test_a_race_whose_simulation_worker_died_is_raced_again_and_an_evaluation_evaluated(
    alice, django_capture_on_commit_callbacks
):
    # The heartbeat's resend (console.recovery.resume_lapsed): a race entry's evaluation is driven
    # by its race task, which scores it after; any other evaluation by its own task.
    model = ready_model(alice)
    cup = event("August cup")
    raced = Submission.objects.create(
        event=cup,
        racer=alice,
        model=model,
        model_name=model.name,
        evaluation=race_evaluation(model, cup),
        status=Submission.Status.IN_PROGRESS,
    )
    plain = EvaluationJob.objects.create(model=model, track=Track.objects.get(name="kidney-bean"))
    with django_capture_on_commit_callbacks() as sent:
        answers = signals.evaluation_lapsed.send(EvaluationJob, evaluation=raced.evaluation)
    assert [answer for _, answer in answers] == [True] and len(sent) == 1
    answers = signals.evaluation_lapsed.send(EvaluationJob, evaluation=plain)
    assert not any(answer for _, answer in answers)
