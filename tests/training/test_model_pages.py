import re

import pytest
from django.urls import reverse

from tests.helpers.training import form_data
from training.models import RLModel, TrainingJob
from training.rewards import EXAMPLES
from training.services import model_create

pytestmark = pytest.mark.django_db


def test_the_create_page_offers_every_setting_with_its_default(client, alice, tracks):
    client.force_login(alice)
    response = client.get(reverse("training:model-create"))
    assert response.status_code == 200
    for text in (
        "Rookie Loop",
        "Object avoidance",
        "Stereo cameras",
        "5-layer CNN",
        "Generate the table",
        "Entropy",
        "SAC alpha (entropy)",
        "Maximum training time",
        "Simulations at once",
        "Use this example",
    ):
        assert text in response.text, text
    assert 'value="rookie-loop" checked' in response.text


def test_the_track_picker_offers_every_catalogue_track_with_its_directions(client, alice, tracks):
    client.force_login(alice)
    page = client.get(reverse("training:model-create")).text
    assert page.count('name="track"') == len(tracks) == 78
    assert "data-track-picker" in page and "data-track-search" in page  # the picker's tools
    assert "{#" not in page and "Expects:" not in page  # its templates' comments stay in them
    assert 'data-track="yun speedway albert 2020"' in page  # what the search box searches
    albert = page[page.index('value="Albert"') :]
    assert albert.split(">")[0].endswith('data-directions="clockwise"')
    wide = page[page.index('value="reInvent2019_wide"') :]
    assert wide.split(">")[0].endswith('data-directions="clockwise counterclockwise"')


def test_a_clockwise_only_track_refuses_counterclockwise_in_the_form(client, alice, tracks):
    client.force_login(alice)
    response = client.post(
        reverse("training:model-create"), form_data(track="Albert", direction="counterclockwise")
    )
    assert response.status_code == 400 and not RLModel.objects.exists()
    assert "Yun Speedway cannot be driven counter-clockwise." in response.text
    response = client.post(
        reverse("training:model-create"), form_data(track="Albert", direction="clockwise")
    )
    assert response.status_code == 302
    model = RLModel.objects.get()
    assert (model.track.display_name, model.direction) == ("Yun Speedway", "clockwise")


def test_a_racer_creates_a_model_and_its_training_is_queued(client, alice, tracks):
    client.force_login(alice)
    response = client.post(reverse("training:model-create"), form_data())
    model = RLModel.objects.get(owner=alice)
    assert response.status_code == 302
    assert response["Location"] == reverse("training:model-detail", args=[model.pk])
    assert [a["steering_angle"] for a in model.action_space] == [-20, 0, 20]
    assert model.jobs.get().status == TrainingJob.Status.QUEUED
    page = client.get(response["Location"])
    assert "Queued: starting on a free trainer" in page.text  # no trainer is busy
    assert "Stop training" in page.text


@pytest.mark.slow
def test_the_model_list_shows_each_models_training_progress(
    client, alice, bob, tracks, django_assert_max_num_queries
):
    ahead = model_create(owner=bob, settings=form_data(name="ahead"))
    model_create(owner=alice, settings=form_data(name="waiting"))
    running = model_create(owner=alice, settings=form_data(name="running"))
    done = model_create(owner=alice, settings=form_data(name="done", max_minutes=10))
    TrainingJob.objects.filter(model=running).update(
        status=TrainingJob.Status.IN_PROGRESS, training_seconds=75.4, iterations=2
    )
    TrainingJob.objects.filter(model=done).update(
        status=TrainingJob.Status.COMPLETED, training_seconds=600, iterations=12
    )
    assert ahead.jobs.get().status == TrainingJob.Status.QUEUED
    client.force_login(alice)
    # session, racer, their racer name (the header), models, jobs, one waiting job, the
    # trainers' jobs
    with django_assert_max_num_queries(10):
        page = client.get(reverse("training:model-list")).text
    rows = {
        name: re.search(rf">{name}</a>.*?</tr>", page, re.S).group(0)
        for name in ("waiting", "running", "done")
    }
    assert "Number 2 in the queue" in rows["waiting"]  # behind bob's
    assert "1:15 used of 60 min, 2 iterations" in rows["running"]
    assert "Completed after 10:00 of 10 min, 12 iterations" in rows["done"]


def test_sac_with_discrete_actions_is_refused_and_the_form_keeps_what_was_typed(
    client, alice, tracks
):
    client.force_login(alice)
    response = client.post(
        reverse("training:model-create"), form_data(algorithm="sac", name="my-sac-car")
    )
    assert response.status_code == 400
    assert "SAC needs a continuous action space" in response.text
    assert 'value="my-sac-car"' in response.text
    assert not RLModel.objects.exists()


def test_a_bad_hyperparameter_is_reported_on_its_field(client, alice, tracks):
    client.force_login(alice)
    response = client.post(reverse("training:model-create"), form_data(**{"clipped_ppo__lr": 1}))
    assert response.status_code == 400
    assert "Learning rate must be between 1e-08 and 0.001." in response.text
    summary = re.search(r"<ul aria-label=\"Sections to fix\">(.*?)</ul>", response.text)[1]
    assert summary == (
        '<li><a href="#section-algorithm">Training algorithm and hyperparameters</a></li>'
    )
    assert 'id="section-algorithm"' in response.text


def test_another_racers_model_is_not_found(client, alice, bob, tracks):
    model = model_create(
        owner=bob,
        settings={
            "name": "bobs",
            "track": "rookie-loop",
            "reward_function": EXAMPLES[0].source,
        },
        validate_reward=False,
    )
    client.force_login(alice)
    assert client.get(reverse("training:model-detail", args=[model.pk])).status_code == 404
    assert client.post(reverse("training:model-stop", args=[model.pk])).status_code == 404
    url = reverse("training:model-file", args=[model.pk, "metrics/training_metrics.json"])
    assert client.get(url).status_code == 404


def test_stop_on_a_queued_model_cancels_it(client, alice, tracks):
    model = model_create(
        owner=alice,
        settings={
            "name": "mine",
            "track": "rookie-loop",
            "reward_function": EXAMPLES[0].source,
        },
        validate_reward=False,
    )
    client.force_login(alice)
    response = client.post(reverse("training:model-stop", args=[model.pk]), follow=True)
    assert "Canceled: the model had not started training." in response.text
    assert model.jobs.get().status == TrainingJob.Status.CANCELED


def test_the_model_page_shows_its_hyperparameters_as_the_create_form_labels_them(
    client, alice, tracks
):
    settings = {**form_data(), "hyperparameters": {"lr": 1e-5, "loss_type": "mean squared error"}}
    model = model_create(owner=alice, settings=settings, validate_reward=False)
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[model.pk])).text

    table = re.search(r"<table [^>]*data-hyperparameters>.*?</table>", page, re.S)[0]
    rows = re.findall(r"<tr><td>([^<]*?) <code.*?<td class=\"num\">(.*?)</td>", table)
    assert rows == [
        ("Gradient descent batch size", "64"),
        ("Number of epochs", "10"),
        ("Learning rate", "1e-5"),
        ("Entropy", "0.01"),
        ("Discount factor", "0.999"),
        ("Loss type", "Mean squared error"),
        ("Episodes between policy updates", "20"),
    ]
    assert '<tr><td>Maximum training time [min]</td><td class="num">60</td></tr>' in table
    others = re.search(r"<details [^>]*data-other-hyperparameters>.*?</details>", page, re.S)[0]
    assert "<summary>Other DeepRacer settings</summary>" in others
    assert '<td>Stack size <code class="setting-key">stack_size</code></td>' in others
    assert "beta_entropy 0.01" not in page  # no run of raw keys
