"""The create-model form: every error from its one real cause, at the field or the action-table
cell it concerns; every number's range and default on the page; what a clone keeps, locked."""

import inspect
import json
import re

import pytest
from django.urls import reverse

from simulator import config as sim
from simulator.env import DeepRacerEnv
from tests.helpers.models import STRAIGHT_AHEAD, ready_model
from tests.helpers.training import field_html, form_data, post
from tests.helpers.training import settings as training_settings
from training import configuration
from training.models import RLModel

pytestmark = pytest.mark.django_db

CONTINUOUS = {
    "action_space_type": "continuous",
    "algorithm": "sac",
    "steering_low": -30,
    "steering_high": 30,
    "speed_low": 1,
    "speed_high": 2,
}


def actions(*rows) -> str:
    return json.dumps(
        [{"steering_angle": s, "speed": v, "index": i} for i, (s, v) in enumerate(rows)]
    )


def test_a_bad_continuous_speed_is_the_only_error_and_shows_under_the_highest_speed(
    client, alice, tracks
):
    response = post(client, alice, **{**CONTINUOUS, "speed_high": 100})
    assert response.status_code == 400
    errors = response.context["form"].errors
    assert errors == {"speed_high": ["The highest speed is 0.1 to 4 m/s, not 100."]}
    assert "SAC needs a continuous action space" not in response.text


def test_a_low_above_its_high_shows_under_the_high(client, alice, tracks):
    response = post(client, alice, **{**CONTINUOUS, "steering_low": 10, "steering_high": -10})
    assert response.context["form"].errors == {
        "steering_high": ["The highest steering angle must be above the lowest, 10 degrees."]
    }


def test_a_blank_continuous_bound_is_named(client, alice, tracks):
    response = post(client, alice, **{**CONTINUOUS, "speed_low": ""})
    assert response.context["form"].errors == {
        "speed_low": ["The lowest speed is blank: enter 0.1 to 4 m/s."]
    }


def test_an_empty_action_table_is_refused_rather_than_replaced_by_the_default(
    client, alice, tracks
):
    response = post(client, alice, actions="[]")
    assert response.status_code == 400
    assert response.context["form"].errors == {
        "actions": ["There are no actions: a discrete action space has 2 to 30."]
    }
    assert not RLModel.objects.exists()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("rows", "index", "columns", "message"),
    [
        (((0, 1), (10, None)), 1, ["speed"], "Speed in action 1 is blank: enter 0.1 to 4 m/s."),
        (((0, 1), ("", 2)), 1, ["steering_angle"], "Steering angle in action 1 is blank"),
        (((0, 1), (10, "fast")), 1, ["speed"],
         "Speed in action 1 must be a number from 0.1 to 4 m/s, not “fast”."),
        (((0, 1), (5, 1), (10, 1), (15, 1), (20, 9)), 4, ["speed"],
         "Speed in action 4 is 0.1 to 4 m/s, not 9."),
        (((0, 1), (10, 1), (0, 1)), 2, ["steering_angle", "speed"],
         "Actions 0 and 2 are the same (0 degrees, 1 m/s): change or remove one."),
    ],
)  # fmt: skip
def test_a_bad_action_is_named_by_its_number_from_0_and_only_its_cells_are_marked(
    client, alice, tracks, rows, index, columns, message
):
    response = post(client, alice, actions=actions(*rows))
    assert response.status_code == 400
    form = response.context["form"]
    [error] = form.action_errors
    assert error["index"] == index and error["columns"] == columns
    assert error["message"].startswith(message)
    assert form.action_table_errors() == []  # the table as a whole is not marked
    marks = json.loads(re.search(r'id="action-errors"[^>]*>(.*?)</script>', response.text)[1])
    assert marks == form.action_errors
    assert 'value="first-model"' in response.text  # what was typed stays


def test_every_bad_cell_is_reported_at_once(alice, tracks):
    space = [{"steering_angle": 45, "speed": 1}, {"steering_angle": 0, "speed": ""}]
    with pytest.raises(configuration.Invalid) as invalid:
        configuration.check(
            training_settings(action_space=space), owner=alice, validate_reward=False
        )
    assert invalid.value.errors == {
        "action_space.0.steering_angle": "Steering angle in action 0 is -30 to 30 degrees, not 45.",
        "action_space.1.speed": "Speed in action 1 is blank: enter 0.1 to 4 m/s.",
    }


def test_a_missing_action_space_still_means_deepracers_default(alice, tracks):
    clean = configuration.check(training_settings(), owner=alice, validate_reward=False)
    assert len(clean.action_space) == len(sim.DEFAULT_ACTION_SPACE)


def test_a_saved_models_settings_check_back_to_themselves(alice, tracks):
    # What a model keeps is what its settings were: its draft (as a racer, an export or the clone
    # page gives them) checks back to the same settings.
    space = {"steering_angle": {"low": -20, "high": 30}, "speed": {"low": 0.8, "high": 2.5}}
    checked = configuration.check(
        training_settings(
            algorithm="sac",
            hyperparameters={"sac_alpha": 0.3},
            action_space=space,
            race_type="HEAD_TO_BOT",
            bots={"count": 2, "speed": 1.5, "lane_changes": True},
            workers=2,
            extra_tracks=["rookie-loop"],
            seed=7,
            evaluation_trials=12,
        ),
        owner=alice,
        validate_reward=False,
    )
    model = RLModel.objects.create(owner=alice, **checked.row())
    saved = configuration.ModelSettings.of(model)
    assert saved.row()["track"] == model.track and saved.hyperparameters["sac_alpha"] == 0.3
    again = configuration.check(
        {**saved.draft(), "name": "again"}, owner=alice, validate_reward=False
    )
    assert again == saved.replace(name="again")


@pytest.mark.parametrize(
    ("name", "attributes", "help_text"),
    [
        ("clipped_ppo__num_epochs", ('min="3"', 'max="10"', 'step="1"'),
         "Range 3-10, default 10 (DeepRacer's default)."),
        ("clipped_ppo__lr", ('min="1e-8"', 'max="0.001"', 'step="any"'),
         "Range 1e-8 to 0.001, default 0.0003 (DeepRacer's default)."),
        ("clipped_ppo__beta_entropy", ('min="0"', 'max="1"'), "Range 0-1, default 0.01"),
        ("clipped_ppo__discount_factor", ('min="0"', 'max="1"'), "Range 0-1, default 0.999"),
        ("clipped_ppo__num_episodes_between_training", ('min="5"', 'max="100"'),
         "Range 5-100, default 20"),
        ("sac__sac_alpha", ('min="0"', 'max="1"'), "Range 0-1, default 0.2"),
        ("steering_low", ('min="-30"', 'max="30"'), "Range -30 to 30, default -30"),
        ("speed_high", ('min="0.1"', 'max="4"', 'step="0.1"'), "Range 0.1-4, default 2"),
        ("box_count", ('min="1"', 'max="6"'), "Range 1-6, default 3"),
        ("bot_speed", ('min="0.2"', 'max="6.0"'), "Range 0.2-6, default 0.2"),
        ("workers", ('min="1"', 'max="4"'), "Range 1-4, default 1"),
        ("evaluation_trials", ('min="1"', 'max="20"', 'step="1"'), "Range 1-20, default 5 "
         "(DeepRacer's default). DeepRacer for Cloud's DR_TRAIN_MIN_EVAL_TRIALS."),
        ("max_minutes", ('min="10"', 'max="600"'),  # a racer's monthly quota is 600 minutes
         "Range 10-1440, default 60 (DeepRacer's default). You have 600 training minutes"),
    ],
)  # fmt: skip
def test_every_number_on_the_create_page_states_its_range_and_default(
    client, alice, tracks, name, attributes, help_text
):
    client.force_login(alice)
    page = client.get(reverse("training:model-create")).text
    for attribute in attributes:
        assert attribute in field_html(page, name), field_html(page, name)
    assert help_text in page
    assert "One of 32, 64, 128, 256, 512; default 64" in page


def test_the_evaluation_episodes_a_checkpoint_drives_are_checked_kept_and_shown(
    client, alice, tracks
):
    refused = post(client, alice, evaluation_trials=0)
    assert refused.status_code == 400 and not RLModel.objects.exists()
    assert refused.context["form"].errors == {
        "evaluation_trials": ["Each checkpoint drives 1 to 20 evaluation episodes (DeepRacer's 5)."]
    }
    post(client, alice, evaluation_trials=12)
    model = RLModel.objects.get()
    assert model.evaluation_trials == 12
    page = client.get(reverse("training:model-detail", args=[model.pk])).text
    assert "Progress (DeepRacer&#x27;s), over 12 evaluation episodes a checkpoint" in page
    clone = client.get(reverse("training:model-create") + f"?clone={model.pk}").text
    assert 'value="12"' in field_html(clone, "evaluation_trials")


def test_the_time_limit_stops_at_the_racers_remaining_minutes(client, alice, tracks):
    client.force_login(alice)
    client.post(reverse("training:model-create"), form_data(max_minutes=560))
    page = client.get(reverse("training:model-create")).text
    assert 'max="40"' in field_html(page, "max_minutes")
    assert "You have 40 training minutes left this month." in page


CLONE_KEEPS = ("vehicle", "camera", "lidar", "network", "algorithm", "action_space_type")


def test_a_clone_shows_what_it_keeps_locked(client, alice, tracks):
    source = ready_model(alice)
    client.force_login(alice)
    page = client.get(reverse("training:model-create") + f"?clone={source.pk}").text
    for name in CLONE_KEEPS:
        assert " disabled" in field_html(page, name), name
    assert "Locked: a clone keeps straight-ahead's network" in page
    assert "a clone keeps straight-ahead's 3 actions" in page
    assert "data-add-action" not in page and "data-generate" not in page


def test_a_clone_takes_what_it_keeps_from_its_source_when_the_browser_sends_none_of_it(
    client, alice, tracks
):
    source = ready_model(alice)
    data = form_data(name="clone", track="pitlane-oval", actions=json.dumps(STRAIGHT_AHEAD))
    for name in CLONE_KEEPS:  # disabled inputs are not sent
        data.pop(name, None)
    client.force_login(alice)
    response = client.post(reverse("training:model-create") + f"?clone={source.pk}", data)
    assert response.status_code == 302, response.context["form"].errors
    clone = RLModel.objects.get(name="clone")
    assert (clone.sensors, clone.network, clone.algorithm, clone.action_space_type) == (
        source.sensors,
        source.network,
        source.algorithm,
        source.action_space_type,
    )


def test_the_loss_type_reads_as_deepracers_and_a_clone_keeps_the_keys_pitlane_does_not_use(
    client, alice, tracks
):
    source = ready_model(alice)
    kept = {"term_cond_avg_score": 350.0, "exploration_type": "e-greedy", "stack_size": 2}
    RLModel.objects.filter(pk=source.pk).update(
        hyperparameters={**source.hyperparameters, **kept, "loss_type": "mean squared error"}
    )
    client.force_login(alice)
    page = client.get(reverse("training:model-create") + f"?clone={source.pk}").text
    loss = re.search(r'<select[^>]*name="clipped_ppo__loss_type".*?</select>', page, re.S)[0]
    assert '<option value="huber">Huber</option>' in loss
    assert '<option value="mean squared error" selected>Mean squared error</option>' in loss
    assert "One of Huber, Mean squared error; default Huber" in page
    data = form_data(
        name="clone",
        track="pitlane-oval",
        actions=json.dumps(STRAIGHT_AHEAD),
        clipped_ppo__loss_type="mean squared error",
    )
    for name in CLONE_KEEPS:
        data.pop(name, None)
    response = client.post(reverse("training:model-create") + f"?clone={source.pk}", data)
    assert response.status_code == 302, response.context["form"].errors
    clone = RLModel.objects.get(name="clone")
    assert {key: clone.hyperparameters[key] for key in kept} == kept
    assert clone.hyperparameters["loss_type"] == "mean squared error"


def test_a_clone_cannot_change_what_it_keeps_even_if_sent(client, alice, tracks):
    source = ready_model(alice)
    response = post(
        client,
        alice,
        reverse("training:model-create") + f"?clone={source.pk}",
        name="clone",
        track="pitlane-oval",
        actions=json.dumps(STRAIGHT_AHEAD),
        network="DEEP_CONVOLUTIONAL_NETWORK",
    )
    assert response.status_code == 400
    assert response.context["form"].errors["network"] == [
        "A clone keeps its source's network: its weights are for that one."
    ]


@pytest.mark.parametrize("race_type", ["TIME_TRIAL", "OBJECT_AVOIDANCE", "HEAD_TO_BOT"])
def test_the_evaluate_page_shows_only_the_chosen_race_types_settings(
    client, alice, tracks, race_type
):
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(race_type=race_type)
    client.force_login(alice)
    page = client.get(reverse("training:evaluation-create", args=[model.pk])).text
    shown = {
        kind: "hidden" not in re.search(rf'<div[^>]*data-when-race="{kind}"[^>]*>', page)[0]
        for kind in ("OBJECT_AVOIDANCE", "HEAD_TO_BOT")
    }
    assert shown == {
        "OBJECT_AVOIDANCE": race_type == "OBJECT_AVOIDANCE",
        "HEAD_TO_BOT": race_type == "HEAD_TO_BOT",
    }
    assert "training/evaluation_create.js" in page


def test_each_setting_is_declared_once_a_column_of_the_model_and_an_argument_of_the_simulator():
    """configuration.ModelSettings is the one list: the row, the archive and the environment are
    derived from it, so each declared setting must be the model's column of the same name and
    each of its environment arguments one the simulator takes."""
    columns = {field.name for field in RLModel._meta.get_fields()}
    assert set(configuration.SETTINGS) <= columns
    arguments = inspect.signature(DeepRacerEnv).parameters
    made = {f.metadata["environment"] for f in configuration.SETTINGS.values()}
    assert made - {""} <= set(arguments)
