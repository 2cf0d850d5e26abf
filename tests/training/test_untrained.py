"""Models with no trained checkpoint (stopped before their first policy update): they say so,
may be evaluated, and are refused for races, downloads and clones."""

import pytest
from django.urls import reverse

from archives import exports
from racing import services as racing_services
from tests.helpers.league import event
from tests.helpers.models import ready_model
from training import artifacts, configuration, selectors, services
from training.models import EvaluationJob, RLModel, TrainingJob

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]

NOT_TRAINED = "Ready: not trained yet (stopped before its first policy update)"


def stopped_before_its_first_update(owner, name: str = "stopped-early") -> RLModel:
    """A READY model whose training stopped before its first policy update: its only
    checkpoint is iteration 0, the weights training started from, as the trainer leaves it."""
    model = ready_model(owner, name)
    job = model.jobs.get()
    start = artifacts.save(model, artifacts.checkpoint(0), artifacts.read(job.last_checkpoint))
    TrainingJob.objects.filter(pk=job.pk).update(
        iterations=0, weights_version=0, last_checkpoint=start, best_checkpoint=start
    )
    return model


def test_a_model_stopped_before_its_first_update_says_it_is_not_trained(client, alice):
    model = stopped_before_its_first_update(alice)
    trained = ready_model(alice, "trained")
    client.force_login(alice)

    page = client.get(reverse("training:model-detail", args=[model.pk])).content.decode()
    assert NOT_TRAINED in page
    assert "No downloads" in page and "physicalmodel-" not in page
    assert "?clone=" not in page
    listing = client.get(reverse("training:model-list")).content.decode()
    assert listing.count(NOT_TRAINED) == 1  # its row, not the trained model's
    trained_page = client.get(reverse("training:model-detail", args=[trained.pk])).content.decode()
    assert NOT_TRAINED not in trained_page and "physicalmodel-trained" in trained_page

    evaluate = client.get(reverse("training:evaluation-create", args=[model.pk])).content.decode()
    assert "not trained yet" in evaluate and "data-untrained" in evaluate
    assert "the weights training started from, not trained yet" in evaluate
    event()
    race = client.get(reverse("racing:submission-create")).content.decode()
    assert f"stopped-early ({NOT_TRAINED})" in race
    assert ">trained</option>" in race


def test_it_may_still_be_evaluated(alice):
    model = stopped_before_its_first_update(alice)
    evaluation = services.evaluation_start(model=model, settings={}, enqueue=False)
    assert evaluation.status == EvaluationJob.Status.QUEUED


def test_it_refuses_to_race_a_model_that_is_not_trained(client, alice):
    model = stopped_before_its_first_update(alice)
    open_event = event()
    with pytest.raises(racing_services.SubmissionRefused, match="not trained yet"):
        racing_services.submission_create(racer=alice, event=open_event, model=model)

    client.force_login(alice)
    response = client.post(
        reverse("racing:submission-create"), {"event": open_event.pk, "model": model.pk}
    )
    assert response.status_code == 200
    assert "nothing to race yet" in response.content.decode()
    assert not EvaluationJob.objects.exists()
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY


def test_it_refuses_to_download_a_model_that_is_not_trained(client, alice):
    model = stopped_before_its_first_update(alice)
    for build in (exports.physical, exports.onnx):
        with pytest.raises(exports.ExportRefused, match="nothing to download"):
            build(model, "best")
    with pytest.raises(exports.ExportRefused, match="nothing to download"):
        exports.virtual(model)

    client.force_login(alice)
    for kind in ("physical", "virtual"):
        url = reverse(f"archives:model-export-{kind}", args=[model.pk])
        response = client.get(url, follow=True)
        assert response.redirect_chain[-1][0] == reverse("training:model-detail", args=[model.pk])
        assert "nothing to download yet" in response.content.decode()


def test_it_cannot_be_cloned(alice):
    model = stopped_before_its_first_update(alice)
    with pytest.raises(configuration.Invalid) as refused:
        services.model_create(
            owner=alice,
            validate_reward=False,
            settings={
                "name": "its-clone",
                "track": "pitlane-oval",
                "cloned_from": model,
                "reward_function": model.reward_function,
                "action_space": model.action_space,
            },
        )
    assert "no trained weights to clone" in str(refused.value.errors)


def test_what_counts_as_trained(alice):
    untrained = stopped_before_its_first_update(alice)
    assert selectors.model_untrained(model=untrained)
    assert selectors.model_trained_checkpoint(model=untrained) is None

    # One update done, but its evaluation had not come in: the best is still the start's
    # weights, so the best a race or download takes is the last iteration's.
    model = ready_model(alice, "one-update")
    job = model.jobs.get()
    start = artifacts.save(model, artifacts.checkpoint(0), artifacts.read(job.last_checkpoint))
    TrainingJob.objects.filter(pk=job.pk).update(best_checkpoint=start)
    assert not selectors.model_untrained(model=model)
    assert selectors.model_trained_checkpoint(model=model) == job.last_checkpoint

    # An import's weights are trained; so are a clone's starting weights (its source's).
    imported = ready_model(alice, "imported")
    job = imported.jobs.get()
    name = artifacts.save(imported, "checkpoints/imported-best.safetensors", b"weights")
    TrainingJob.objects.filter(pk=job.pk).update(last_checkpoint=name, best_checkpoint=name)
    assert not selectors.model_untrained(model=imported)
    clone = stopped_before_its_first_update(alice, "a-clone")
    artifacts.save(clone, artifacts.CLONED_WEIGHTS, b"its source's best weights")
    assert not selectors.model_untrained(model=clone)
