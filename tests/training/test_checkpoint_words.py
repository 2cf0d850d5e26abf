"""An evaluation says which iteration its checkpoint is, and the pages of a model say it in a
racer's words: no internal status names, no track slugs."""

import re

import pytest
from django.urls import reverse

from jobs import evaluation
from tests.helpers.models import ready_model
from training import artifacts, selectors, services
from training.models import EvaluationJob, EvaluationTrial, Iteration, RLModel, Track

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def trained_for_five_iterations(owner) -> RLModel:
    """A ready model whose best checkpoint is iteration 3 (85% in evaluation, a mean reward of
    120.5, a mean lap of 12.345 s) and whose last is iteration 5 (60%)."""
    model = ready_model(owner)
    job = model.jobs.get()
    weights = artifacts.read(job.last_checkpoint)
    names = {n: artifacts.save(model, artifacts.checkpoint(n), weights) for n in (3, 5)}
    job.best_checkpoint, job.last_checkpoint, job.iterations = names[3], names[5], 5
    job.save()
    for number in range(1, 6):
        Iteration.objects.create(
            job=job,
            number=number,
            reward=10.0 * number,
            completion=12.0 * number,
            evaluation_completion={3: 85.0, 5: 60.0}.get(number, 20.0),
            evaluation_reward={3: 120.5, 5: 80.0}.get(number, 10.0),
            evaluation_lap_ms={3: 12_345.0, 5: 999_999.0}.get(number, 999_999.0),
            episodes=5,
            steps=500,
            wall_seconds=1.0,
        )
    return model


def visible_text(html: str) -> str:
    """What a racer reads: the page without its tags, scripts and attributes."""
    html = re.sub(r"<(script|style)\b.*?</\1>", " ", html, flags=re.S)
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html))


@pytest.fixture
def evaluated(monkeypatch):
    """Run an evaluation of a model through the path every evaluation and race takes, up to
    the weights it drives with; the driving itself is another test's business."""
    monkeypatch.setattr(evaluation.Race, "_drive", lambda *args: None)
    monkeypatch.setattr(evaluation.EvaluationCar, "_save", lambda *args: None)

    def run(model: RLModel, which: str) -> EvaluationJob:
        started = services.evaluation_start(
            model=model, settings={"trials": 3, "checkpoint": which}, enqueue=False
        )
        evaluation.run(started.pk)
        return EvaluationJob.objects.get(pk=started.pk)

    return run


def test_an_evaluation_records_the_iteration_of_the_checkpoint_it_drove(client, alice, evaluated):
    model = trained_for_five_iterations(alice)

    best = evaluated(model, "best")

    assert best.status == EvaluationJob.Status.COMPLETED, best.failure_reason
    assert best.checkpoint_iteration == 3
    assert best.checkpoint_name == artifacts.path(model, artifacts.checkpoint(3))
    client.force_login(alice)
    page = client.get(reverse("training:evaluation-detail", args=[model.pk, best.pk]))
    assert "Best checkpoint (iteration 3)" in visible_text(page.content.decode())

    last = evaluated(model, "last")

    assert last.checkpoint_iteration == 5
    page = client.get(reverse("training:evaluation-detail", args=[model.pk, last.pk]))
    assert "Last checkpoint (iteration 5)" in visible_text(page.content.decode())


def test_imported_weights_have_no_iteration(alice):
    assert artifacts.checkpoint_iteration("models/4/checkpoints/imported-best.safetensors") is None
    assert artifacts.checkpoint_iteration("models/4/checkpoints/iteration-12.safetensors") == 12


def test_the_evaluate_form_and_the_downloads_name_each_checkpoint_by_its_iteration(client, alice):
    model = trained_for_five_iterations(alice)
    client.force_login(alice)

    form = visible_text(
        client.get(reverse("training:evaluation-create", args=[model.pk])).content.decode()
    )
    detail = visible_text(
        client.get(reverse("training:model-detail", args=[model.pk])).content.decode()
    )

    for text in (form, detail):
        assert "Best: iteration 3, 85% evaluation completion" in text
        assert "Last: iteration 5, 60% evaluation completion" in text


def test_a_models_pages_show_no_internal_status_names_or_track_slugs(client, alice):
    model = trained_for_five_iterations(alice)
    RLModel.objects.filter(pk=model.pk).update(workers=3, extra_tracks=["rookie-loop", "s-bend"])
    raced = EvaluationJob.objects.create(
        model=model,
        track=Track.objects.get(name="rookie-loop"),
        trials=3,
        status=EvaluationJob.Status.COMPLETED,
        checkpoint_iteration=3,
    )
    for number, status in enumerate(["lap_complete", "lap_complete", "time_up"], start=1):
        EvaluationTrial.objects.create(
            evaluation=raced,
            number=number,
            time_ms=20_000,
            status=status,
            progress=100.0 if status == "lap_complete" else 40.0,
        )
    client.force_login(alice)

    pages = {
        name: visible_text(client.get(url).content.decode())
        for name, url in {
            "model": reverse("training:model-detail", args=[model.pk]),
            "evaluation": reverse("training:evaluation-detail", args=[model.pk, raced.pk]),
            "models": reverse("training:model-list"),
            "evaluate": reverse("training:evaluation-create", args=[model.pk]),
        }.items()
    }

    for name, text in pages.items():
        for raw in ("lap_complete", "time_up", "rookie-loop", "s-bend", "pitlane-oval"):
            assert raw not in text, f"{raw!r} is shown on the {name} page"
    assert "Rookie Loop" in pages["model"] and "S-Bend" in pages["model"]
    assert pages["evaluation"].count("Lap complete") == 2
    assert "Time up" in pages["evaluation"]


def test_the_model_page_says_which_checkpoint_each_evaluation_drove_and_how_best_is_picked(
    client, alice, evaluated
):
    model = trained_for_five_iterations(alice)
    RLModel.objects.filter(pk=model.pk).update(best_checkpoint_by="laptime")
    best, last = evaluated(model, "best"), evaluated(model, "last")
    client.force_login(alice)

    page = visible_text(
        client.get(reverse("training:model-detail", args=[model.pk])).content.decode()
    )

    assert "Best checkpoint by Lap time" in page
    assert f"Best checkpoint (iteration 3) · seed {best.seed}" in page
    assert f"Last checkpoint (iteration 5) · seed {last.seed}" in page
    # The downloads: the figure that made it best, the last's completion.
    assert "Best by lap time: iteration 3, 12.345 s mean evaluation lap time" in page
    assert "Last: iteration 5, 60% evaluation completion" in page


def test_a_best_by_reward_is_named_with_its_mean_evaluation_reward(alice):
    model = trained_for_five_iterations(alice)
    RLModel.objects.filter(pk=model.pk).update(best_checkpoint_by="reward")
    model.refresh_from_db()

    labels = [choice.label for choice in selectors.model_checkpoint_choices(model=model)]

    assert labels == [
        "Best by reward: iteration 3, 120.5 mean evaluation reward",
        "Last: iteration 5, 60% evaluation completion",
    ]


def test_every_page_names_the_starting_weights_alike_never_as_iteration_0(client, alice):
    model = trained_for_five_iterations(alice)
    started = EvaluationJob.objects.create(
        model=model,
        track=Track.objects.get(name="rookie-loop"),
        trials=3,
        status=EvaluationJob.Status.COMPLETED,
        checkpoint="last",
        checkpoint_iteration=0,
    )
    client.force_login(alice)

    for url in (
        reverse("training:model-detail", args=[model.pk]),
        reverse("training:evaluation-detail", args=[model.pk, started.pk]),
    ):
        text = visible_text(client.get(url).content.decode())
        assert "Last checkpoint (the weights training started from)" in text
        assert "iteration 0" not in text
