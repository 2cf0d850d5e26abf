"""Domain randomisation, a model's training option (off by default, as in DeepRacer): it travels
from the create-model page into the environment the model trains in, onto its page, into a
clone and through our own export; an evaluation may drive its trials in randomised scenes
whatever the model trained in, from the Evaluate page or ``manage.py evaluate --randomise``."""

import io
import json

import gymnasium
import pytest
import yaml
from django.core.management import call_command
from django.urls import reverse

import simulator
from archives import exports, imports
from simulator import randomisation_ranges
from simulator.randomisation import LookView
from tests.helpers.archives import DEEPRACER_PARAMS, deepracer_export, tar_gz
from tests.helpers.evaluations import EVALUATION_FORM
from tests.helpers.models import ready_model, trained_model
from tests.helpers.training import post
from tests.helpers.training import settings as training_settings
from training import artifacts, configuration, services
from training.forms import ModelCreateForm
from training.models import EvaluationJob, RLModel

pytestmark = pytest.mark.django_db


def test_a_racer_who_ticks_it_trains_in_a_new_scene_each_episode(client, alice, tracks):
    response = post(client, alice, domain_randomisation="on")
    model = RLModel.objects.get(owner=alice)
    assert response.status_code == 302 and model.domain_randomisation
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings()).unwrapped
    env.reset(seed=1)
    first = env.look
    env.reset()
    assert isinstance(env._cameras[0], LookView) and env.look != first
    page = client.get(reverse("training:model-detail", args=[model.pk]))
    assert "Domain randomisation: each episode in a scene of its own" in page.text
    varies = dict(randomisation_ranges.describe())  # what it varies, by how much: the one source
    assert f"Car ({varies['Car']})" in page.text and "motor x0.98-1.02" in varies["Car"]


def test_a_model_made_without_ticking_it_trains_in_the_plain_scene(client, alice, tracks):
    post(client, alice)
    model = RLModel.objects.get(owner=alice)
    assert model.domain_randomisation is False
    assert model.environment_settings()["randomise"] is False
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings()).unwrapped
    env.reset(seed=1)
    assert env._scene is None and not hasattr(env, "look")
    page = client.get(reverse("training:model-detail", args=[model.pk]))
    assert "DeepRacer's plain scene (no domain randomisation)" in page.text


def test_the_create_page_offers_it_with_a_line_that_says_what_it_does(client, alice, tracks):
    client.force_login(alice)
    page = client.get(reverse("training:model-create")).text
    assert 'name="domain_randomisation"' in page
    assert "DR_ENABLE_DOMAIN_RANDOMIZATION" in page and "Off by default, as in DeepRacer." in page


def test_anything_but_on_or_off_is_refused_in_words(alice, tracks):
    with pytest.raises(configuration.Invalid) as refused:
        configuration.check(
            training_settings(domain_randomisation="yes"), owner=alice, validate_reward=False
        )
    assert refused.value.errors == {
        "domain_randomisation": "Domain randomisation is on or off: true or false."
    }


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_clone_and_our_own_export_keep_it(alice, bob, tracks):
    original = trained_model(alice, "shifty", domain_randomisation=True)
    clone_page = ModelCreateForm.initial_from(configuration.ModelSettings.of(original))
    assert clone_page["domain_randomisation"] is True
    ours = exports.pitlane_settings(original)
    assert ours["domain_randomisation"] is True
    archive = deepracer_export(**{exports.PITLANE_SETTINGS: json.dumps(ours).encode()})
    imported = imports.import_model(owner=bob, archive=io.BytesIO(tar_gz(archive)))
    assert imported.model.domain_randomisation is True


@pytest.mark.parametrize(("given", "expected"), [("True", True), ("sometimes", False)])
def test_a_deepracer_archive_brings_its_enable_domain_randomization(given, expected, alice, tracks):
    params = {**DEEPRACER_PARAMS, "ENABLE_DOMAIN_RANDOMIZATION": given}
    archive = deepracer_export(**{"training_params.yaml": yaml.safe_dump(params).encode()})
    imported = imports.import_model(owner=alice, archive=io.BytesIO(tar_gz(archive)))
    assert imported.model.domain_randomisation is expected
    notes = [note for note in imported.notes if "ENABLE_DOMAIN_RANDOMIZATION" in note]
    assert notes == (
        [
            "Not carried over from training_params.yaml: ENABLE_DOMAIN_RANDOMIZATION sometimes, "
            "neither true nor false. Domain randomisation is off."
        ]
        if given == "sometimes"
        else []
    )


def test_training_params_carry_it_and_the_best_metric_through_a_deepracer_archive(
    alice, bob, tracks
):
    """Without our pitlane.json, training_params.yaml alone brings them back, spelt as DeepRacer
    for Cloud writes them (ENABLE_DOMAIN_RANDOMIZATION, BEST_MODEL_METRIC, MIN_EVAL_TRIALS)."""
    original = trained_model(
        alice,
        "shifty",
        domain_randomisation=True,
        best_checkpoint_by="laptime",
        evaluation_trials=12,
    )
    params = artifacts.training_params(original)
    written = ("ENABLE_DOMAIN_RANDOMIZATION", "BEST_MODEL_METRIC", "MIN_EVAL_TRIALS")
    assert [params[key] for key in written] == [True, "laptime", 12]
    params["MIN_EVAL_TRIALS"] = "12"  # as DeepRacer for Cloud writes it: prepare-config.py:55
    archive = deepracer_export(**{"training_params.yaml": yaml.safe_dump(params).encode()})
    imported = imports.import_model(owner=bob, archive=io.BytesIO(tar_gz(archive)))
    model = imported.model
    assert (model.domain_randomisation, model.best_checkpoint_by, model.evaluation_trials) == (
        True,
        "laptime",
        12,
    )
    assert not [note for note in imported.notes if "BEST_MODEL_METRIC" in note]
    assert not [note for note in imported.notes if "MIN_EVAL_TRIALS" in note]


@pytest.mark.parametrize(
    ("given", "kept"), [(None, 5), ("0", 1), ("50", 20), ("lots", 5), (7.5, 5)]
)
def test_evaluation_trials_this_console_cannot_take_are_brought_within_its_range_with_a_note(
    alice, tracks, given, kept
):
    params = {**DEEPRACER_PARAMS, "MIN_EVAL_TRIALS": given}
    archive = deepracer_export(**{"training_params.yaml": yaml.safe_dump(params).encode()})
    imported = imports.import_model(owner=alice, archive=io.BytesIO(tar_gz(archive)))
    assert imported.model.evaluation_trials == kept
    notes = [note for note in imported.notes if "MIN_EVAL_TRIALS" in note]
    assert notes == (
        []
        if given is None
        else [
            f"Not carried over from training_params.yaml: MIN_EVAL_TRIALS {given}. Each "
            f"checkpoint drives 1 to 20 evaluation episodes here; this one drives {kept}."
        ]
    )


def test_a_best_model_metric_deepracer_does_not_know_is_noted_and_progress_kept(alice, tracks):
    params = {**DEEPRACER_PARAMS, "BEST_MODEL_METRIC": "speed"}
    archive = deepracer_export(**{"training_params.yaml": yaml.safe_dump(params).encode()})
    imported = imports.import_model(owner=alice, archive=io.BytesIO(tar_gz(archive)))
    assert imported.model.best_checkpoint_by == "progress"
    assert (
        "Not carried over from training_params.yaml: BEST_MODEL_METRIC speed, neither "
        "progress, reward nor laptime." in " ".join(imported.notes)
    )


def test_an_evaluation_drives_in_randomised_scenes_only_when_asked(alice, tracks):
    model = trained_model(alice, "shifty", domain_randomisation=True)
    plain = services.evaluation_start(model=model, settings={}, enqueue=False)
    assert plain.domain_randomisation is False
    assert plain.environment_settings()["randomise"] is False  # not the model's training option
    plain.delete()
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.READY)
    asked = services.evaluation_start(
        model=model, settings={"domain_randomisation": True}, enqueue=False
    )
    assert asked.environment_settings()["randomise"] is True


def test_the_evaluate_page_offers_randomised_scenes(client, alice, tracks):
    model = ready_model(alice)
    client.force_login(alice)
    url = reverse("training:evaluation-create", args=[model.pk])
    assert 'name="domain_randomisation"' in client.get(url).text
    response = client.post(
        url,
        {**EVALUATION_FORM, "domain_randomisation": "on"},
    )
    assert response.status_code == 302
    evaluation = EvaluationJob.objects.get()
    assert evaluation.domain_randomisation and not model.domain_randomisation
    detail = client.get(response["Location"]).text
    assert "randomised scenes" in detail


def test_manage_py_evaluate_randomise_drives_the_trials_in_randomised_scenes(alice, tracks, capsys):
    model = ready_model(alice)
    call_command(
        "evaluate",
        model.name,
        "--track",
        "pitlane-oval",
        "--trials",
        "3",
        "--max-resets",
        "0",
        "--randomise",
    )
    evaluation = EvaluationJob.objects.get(model=model)
    assert evaluation.status == EvaluationJob.Status.COMPLETED
    assert evaluation.domain_randomisation
    assert "randomised scenes" in capsys.readouterr().out
