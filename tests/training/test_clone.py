"""Clone: a new model, the wizard filled in from its source, that trains on from the source's
weights; what the weights depend on cannot change."""

import json

import pytest
from django.urls import reverse

from rl.learner import load_tensors
from tests.helpers.models import (
    STRAIGHT_AHEAD,
    ready_model,
    trained_model,
    with_a_later_checkpoint,
)
from tests.helpers.training import form_data, wait_for_job
from tests.helpers.training import settings as training_settings
from training import artifacts
from training.configuration import ModelSettings
from training.forms import ModelCreateForm
from training.models import RLModel
from training.services import model_create, training_stop

pytestmark = pytest.mark.django_db


def clone_url(model: RLModel) -> str:
    return reverse("training:model-create") + f"?clone={model.pk}"


def cloned_form(**changes) -> dict:
    clone = {
        "name": "straight-ahead-clone",
        "track": "pitlane-oval",
        "actions": json.dumps(STRAIGHT_AHEAD),
    }
    return form_data(**{**clone, **changes})


def test_the_wizard_is_filled_in_from_the_source(alice, tracks, client):
    source = ready_model(alice)
    client.force_login(alice)
    page = client.get(clone_url(source)).text
    assert "Clone straight-ahead" in page
    assert 'value="straight-ahead-clone"' in page
    assert 'value="pitlane-oval" checked' in page
    assert "def reward_function" in page
    assert "Clone</a>" in client.get(reverse("training:model-detail", args=[source.pk])).text


def test_a_clone_starts_from_the_sources_best_weights(alice, tracks, client):
    source = ready_model(alice)
    client.force_login(alice)
    response = client.post(clone_url(source), cloned_form(max_minutes=30))
    assert response.status_code == 302
    clone = RLModel.objects.get(name="straight-ahead-clone")
    assert clone.cloned_from == source and clone.max_minutes == 30
    assert clone.status == RLModel.Status.QUEUED
    best = source.jobs.get().best_checkpoint
    assert artifacts.read(artifacts.path(clone, artifacts.CLONED_WEIGHTS)) == artifacts.read(best)


def test_a_clone_may_start_from_the_sources_last_weights_and_says_so(alice, tracks, client):
    source = with_a_later_checkpoint(ready_model(alice))
    job = source.jobs.get()
    artifacts.save(source, artifacts.checkpoint(2), b"not the best weights")
    client.force_login(alice)
    page = client.get(clone_url(source)).text
    assert "Best: iteration 1" in page and "Last: iteration 2" in page  # the choice, named
    response = client.post(clone_url(source), cloned_form(cloned_checkpoint="last"))
    assert response.status_code == 302
    clone = RLModel.objects.get(name="straight-ahead-clone")
    assert clone.cloned_checkpoint == "last"
    copied = artifacts.read(artifacts.path(clone, artifacts.CLONED_WEIGHTS))
    assert copied == artifacts.read(job.last_checkpoint) == b"not the best weights"
    shown = client.get(reverse("training:model-detail", args=[clone.pk])).text
    assert "straight-ahead</a>, its last checkpoint" in shown


def test_a_clone_of_a_checkpoint_that_is_neither_best_nor_last_is_refused(alice, tracks, client):
    source = ready_model(alice)
    client.force_login(alice)
    response = client.post(clone_url(source), cloned_form(cloned_checkpoint="first"))
    assert response.status_code == 400
    assert response.context["form"].errors["cloned_checkpoint"]
    assert not RLModel.objects.filter(name="straight-ahead-clone").exists()


@pytest.mark.slow
@pytest.mark.parametrize("settings", [
    {},
    {"algorithm": "sac", "hyperparameters": {}, "race_type": "OBJECT_AVOIDANCE",
     "action_space": {"steering_angle": {"low": -25, "high": 20}, "speed": {"low": 0.5,
                                                                           "high": 3.5}},
     "boxes": {"count": 4, "randomize": True}, "description": "boxes ahead", "max_minutes": 45},
    {"race_type": "HEAD_TO_BOT", "bots": {"count": 2, "speed": 0.8, "lane_changes": True},
     "sensors": ["STEREO_CAMERAS", "SECTOR_LIDAR"], "network": "DEEP_CONVOLUTIONAL_NETWORK"},
])  # fmt: skip
def test_a_clone_posted_as_the_page_shows_it_has_every_setting_of_its_source(
    settings, alice, tracks, client
):
    # The settings make one round: the page shows them (initial_from), the form gives them back
    # (settings), configuration checks them and the service saves them.
    source = trained_model(alice, "source", **settings)
    shown = ModelCreateForm.initial_from(ModelSettings.of(source))
    client.force_login(alice)
    posted = {name: "" if value is None else value for name, value in shown.items()}
    response = client.post(clone_url(source), {**form_data(), **posted})
    assert response.status_code == 302, response.context["form"].errors
    clone = RLModel.objects.get(cloned_from=source)
    assert ModelSettings.of(clone) == ModelSettings.of(source).replace(
        name="source-clone", cloned_from=source, cloned_checkpoint="best"
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"camera": "STEREO_CAMERAS"}, "A clone keeps its source&#x27;s sensors"),
        ({"actions": json.dumps(STRAIGHT_AHEAD[:2])}, "number of actions (3)"),
        ({"network": "DEEP_CONVOLUTIONAL_NETWORK"}, "keeps its source&#x27;s network"),
        ({"action_space_type": "continuous", "algorithm": "sac"}, "training algorithm"),
    ],
)
def test_what_the_weights_depend_on_cannot_change(changes, message, alice, tracks, client):
    source = ready_model(alice)
    client.force_login(alice)
    response = client.post(clone_url(source), cloned_form(**changes))
    assert response.status_code == 400
    assert message in response.text
    assert 'value="straight-ahead-clone"' in response.text  # what was typed stays
    assert not RLModel.objects.filter(name="straight-ahead-clone").exists()


def test_only_a_ready_model_of_ones_own_can_be_cloned(alice, bob, tracks, client):
    source = ready_model(alice)
    client.force_login(bob)
    assert client.get(clone_url(source)).status_code == 404
    assert client.post(clone_url(source), cloned_form()).status_code == 404

    RLModel.objects.filter(pk=source.pk).update(status=RLModel.Status.TRAINING)
    client.force_login(alice)
    response = client.post(clone_url(source), cloned_form())
    assert response.status_code == 400
    assert "Only a ready model can be cloned." in response.text


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_the_clones_training_starts_from_those_weights(alice, tracks, celery_worker_process):
    source = ready_model(alice)
    clone = model_create(
        owner=alice,
        settings=training_settings(
            name="clone-trains", action_space=STRAIGHT_AHEAD, cloned_from=source
        ),
    )
    job = wait_for_job(clone.jobs.get(), lambda j: j.last_checkpoint, "the first checkpoint")
    training_stop(job=job)
    assert job.log_lines.filter(text__startswith="Starting from the weights").exists()
    start = load_tensors(artifacts.read(job.last_checkpoint))
    assert start["action_net.bias"].tolist() == [0.0, 10.0, 0.0]  # the source's straight ahead
    wait_for_job(job, lambda j: not j.is_active, "the stop", 120)
