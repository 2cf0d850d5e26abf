"""The API's doors to a racer's models and reward functions: the same rules and words as the
pages (their services), refusals as JSON with a code."""

from __future__ import annotations

import io
import json
import tarfile

import pytest
import yaml

from archives import logs_archive
from tests.helpers.accounts import api_token
from tests.helpers.archives import DEEPRACER_HYPERPARAMETERS, DEEPRACER_METADATA, DEEPRACER_PARAMS
from tests.helpers.models import ready_model, with_a_later_checkpoint
from tests.helpers.training import settings as training_settings
from training import artifacts, configuration, services
from training.models import EvaluationJob, Iteration, RLModel, TrainingJob
from training.rewards import EXAMPLES

MODELS, VALIDATE = "/api/v1/models", "/api/v1/reward-functions/validate"


def a_model(owner, name: str = "mine", status=RLModel.Status.READY) -> RLModel:
    checked = configuration.check(training_settings(name=name), owner=owner, validate_reward=False)
    return services.model_insert(owner=owner, settings=checked, status=status)


def test_a_queued_training_is_canceled_and_a_model_not_training_is_refused(alice, tracks, client):
    model = a_model(alice, status=RLModel.Status.QUEUED)
    job = TrainingJob.objects.create(model=model)
    token = api_token(alice, "read", "train")
    stopped = client.post(f"{MODELS}/{model.pk}/stop", **token)
    assert stopped.status_code == 200 and stopped.json()["status"] == "CANCELED"
    job.refresh_from_db()
    assert job.status == TrainingJob.Status.CANCELED
    again = client.post(f"{MODELS}/{model.pk}/stop", **token)
    assert again.status_code == 409 and again.json() == {
        "code": "not_training",
        "message": "This model is not training.",
    }
    reader = client.post(f"{MODELS}/{model.pk}/stop", **api_token(alice, "read"))
    assert reader.status_code == 403 and reader.json()["code"] == "scope"


def test_a_model_is_deleted_once_nothing_runs_on_it_and_never_anothers(alice, bob, tracks, client):
    busy = a_model(alice, "busy", status=RLModel.Status.TRAINING)
    done = a_model(alice, "done")
    refused = client.delete(f"{MODELS}/{busy.pk}", **api_token(alice, "train"))
    assert refused.status_code == 409 and refused.json()["code"] == "busy"
    assert "stop its training first" in refused.json()["message"]
    assert client.delete(f"{MODELS}/{done.pk}", **api_token(bob, "train")).status_code == 404
    deleted = client.delete(f"{MODELS}/{done.pk}", **api_token(alice, "train"))
    assert deleted.status_code == 200 and "files_removed" in deleted.json()
    assert list(RLModel.objects.values_list("name", flat=True)) == ["busy"]


def test_a_models_iterations_are_the_training_graphs_points(alice, tracks, client):
    model = a_model(alice)
    assert client.get(f"{MODELS}/{model.pk}/iterations", **api_token(alice, "read")).json() == []
    job = TrainingJob.objects.create(model=model, status=TrainingJob.Status.COMPLETED)
    for number, reward in ((1, 10.0), (2, 25.5)):
        Iteration.objects.create(
            job=job,
            number=number,
            reward=reward,
            completion=40.0 * number,
            episodes=20,
            steps=900 * number,
            wall_seconds=60.0,
        )
    points = client.get(f"{MODELS}/{model.pk}/iterations", **api_token(alice, "read")).json()
    assert [(p["number"], p["reward"], p["completion"]) for p in points] == [
        (1, 10.0, 40.0),
        (2, 25.5, 80.0),
    ]


@pytest.mark.slow  # the sandbox runs the code
def test_validate_answers_as_the_editors_button_does(alice, tracks, client):
    token = api_token(alice, "train")
    good = client.post(
        VALIDATE,
        {"source": EXAMPLES[0].source, "track": "pitlane-oval"},
        content_type="application/json",
        **token,
    )
    assert good.status_code == 200 and good.json()["valid"] is True
    assert good.json()["samples"] and all(s["reward"] is not None for s in good.json()["samples"])
    broken = client.post(
        VALIDATE,
        {"source": "def reward_function(params)\n    return 1.0\n"},
        content_type="application/json",
        **token,
    )
    assert broken.status_code == 200 and broken.json()["valid"] is False
    assert broken.json()["errors"][0]["line"] == 1
    unknown = client.post(
        VALIDATE, {"source": "x", "track": "the-moon"}, content_type="application/json", **token
    )
    assert unknown.status_code == 400 and unknown.json()["message"] == "Choose a listed track."
    missing = client.post(VALIDATE, {}, content_type="application/json", **token)
    assert missing.status_code == 400 and missing.json()["code"] == "invalid"
    reader = client.post(
        VALIDATE, {"source": "x"}, content_type="application/json", **api_token(alice, "read")
    )
    assert reader.status_code == 403


@pytest.mark.slow  # the sandbox runs the code
def test_the_reward_function_library_is_kept_as_the_editor_keeps_it(alice, bob, tracks, client):
    token, library = api_token(alice, "read", "train"), "/api/v1/reward-functions"
    saved = client.post(
        library, {"name": "centre", "source": EXAMPLES[0].source}, "application/json", **token
    )
    assert saved.status_code == 201, saved.json()
    function = saved.json()
    assert client.get(library, **token).json() == [function]
    broken = client.put(
        f"{library}/{function['id']}",
        {"name": "centre", "source": "def reward_function(params)\n    return 1.0\n"},
        "application/json",
        **token,
    )
    assert broken.status_code == 400
    assert broken.json()["errors"]["source"].startswith("It was not saved: the code has 1 error")
    assert "Line 1:" in broken.json()["errors"]["source"]
    taken = client.post(
        library, {"name": "CENTRE", "source": EXAMPLES[0].source}, "application/json", **token
    )
    assert (
        taken.status_code == 400
        and "already have a reward function" in taken.json()["errors"]["name"]
    )
    renamed = client.put(
        f"{library}/{function['id']}",
        {"name": "follow the line", "source": EXAMPLES[1].source},
        "application/json",
        **token,
    )
    assert renamed.status_code == 200 and renamed.json()["source"] == EXAMPLES[1].source
    assert client.get(f"{library}/{function['id']}", **api_token(bob, "read")).status_code == 404
    assert (
        client.delete(f"{library}/{function['id']}", **api_token(bob, "train")).status_code == 404
    )
    assert client.delete(f"{library}/{function['id']}", **token).status_code == 204
    assert client.get(library, **token).json() == []


def drfc_files(**changes) -> dict[str, str]:
    """A DeepRacer for Cloud model folder's files, as `pitlane train FOLDER` sends them."""
    return {
        "model_metadata.json": json.dumps(DEEPRACER_METADATA),
        "hyperparameters.json": json.dumps(DEEPRACER_HYPERPARAMETERS),
        "training_params.yaml": yaml.safe_dump({**DEEPRACER_PARAMS, "WORLD_NAME": "Oval_track"}),
        "reward_function.py": EXAMPLES[0].source,
        **changes,
    }


@pytest.mark.slow  # the sandbox validates the reward function
def test_a_model_is_created_from_a_deepracer_for_cloud_folders_files(alice, tracks, client):
    token = api_token(alice, "read", "train")
    # DeepRacer for Cloud writes these as text (scripts/training/prepare-config.py:54-58, 2eb1a1f)
    params = {
        **DEEPRACER_PARAMS,
        "WORLD_NAME": "Oval_track",
        "NUM_WORKERS": 2,
        "BEST_MODEL_METRIC": "laptime",
        "MIN_EVAL_TRIALS": "12",
    }
    files = drfc_files(**{"training_params.yaml": yaml.safe_dump(params)})
    body = {"files": files, "name": "from-drfc", "max_minutes": 15}
    created = client.post(MODELS, body, content_type="application/json", **token)
    assert created.status_code == 201, created.json()
    answer = created.json()
    model = RLModel.objects.get(owner=alice)
    assert answer["id"] == model.pk and answer["name"] == "from-drfc"
    assert answer["status"] == "QUEUED" and model.max_minutes == 15
    assert (
        model.track.name == "Oval_track" and model.network == DEEPRACER_METADATA["neural_network"]
    )
    assert [a["speed"] for a in model.action_space] == [0.6, 1.2, 0.6]
    assert model.hyperparameters["num_episodes_between_training"] == 20
    assert model.latest_job.status == TrainingJob.Status.QUEUED
    detail = client.get(f"{MODELS}/{model.pk}", **token).json()
    shown = {"direction": model.direction, "race_type": "TIME_TRIAL", "workers": 2,
             "best_checkpoint_by": "laptime", "evaluation_trials": 12, "seed": model.seed,
             "domain_randomisation": False}  # fmt: skip
    assert {key: detail[key] for key in shown} == shown

    broken = drfc_files(**{"reward_function.py": "def reward_function(params)\n    return 1\n"})
    refused = client.post(
        MODELS, {"files": broken, "name": "b"}, content_type="application/json", **token
    )
    assert refused.status_code == 400 and refused.json()["code"] == "reward_invalid"
    assert refused.json()["message"].startswith("reward_function.py (line 1):")
    unknown = drfc_files(**{"model_metadata.json": json.dumps({"training_algorithm": "dqn"})})
    refused = client.post(
        MODELS, {"files": unknown, "name": "c"}, content_type="application/json", **token
    )
    assert refused.status_code == 400 and "clipped_ppo" in refused.json()["message"]
    no_metadata = {"reward_function.py": EXAMPLES[0].source}
    refused = client.post(MODELS, {"files": no_metadata}, content_type="application/json", **token)
    assert refused.json()["message"] == (
        "files must hold model_metadata.json and reward_function.py."
    )
    taken = client.post(MODELS, body, content_type="application/json", **token)
    assert taken.status_code == 400 and "name" in taken.json()["errors"]
    assert RLModel.objects.count() == 1


def test_an_evaluation_starts_is_listed_read_and_stopped_under_the_pages_rules(
    alice, bob, tracks, client, own_storage
):
    model = ready_model(alice)
    token = api_token(alice, "read", "train")
    url = f"{MODELS}/{model.pk}/evaluations"
    bad = client.post(url, {"trials": 9}, content_type="application/json", **token)
    assert bad.status_code == 400 and bad.json()["errors"] == {
        "trials": "An evaluation has 3 to 5 trials."
    }
    started = client.post(
        url, {"trials": 4, "max_resets": 0, "seed": 7}, content_type="application/json", **token
    )
    assert started.status_code == 201
    evaluation = started.json()
    assert (evaluation["status"], evaluation["trials"], evaluation["seed"]) == ("QUEUED", 4, 7)
    assert evaluation["track"] == model.track.name and evaluation["results"] == []
    model.refresh_from_db()
    assert model.status == RLModel.Status.EVALUATING
    busy = client.post(url, {}, content_type="application/json", **token)
    assert busy.status_code == 409 and "evaluating" in busy.json()["message"]

    listed = client.get(url, **token).json()
    assert [e["id"] for e in listed] == [evaluation["id"]]
    assert client.get(url, **api_token(bob, "read")).status_code == 404
    one = f"{url}/{evaluation['id']}"
    assert client.get(one, **token).json()["id"] == evaluation["id"]
    stopped = client.post(f"{one}/stop", **token)
    assert stopped.status_code == 200 and stopped.json()["status"] == "CANCELED"
    model.refresh_from_db()
    assert model.status == RLModel.Status.READY

    # Its video, as a finished one has it, in storage of the test's own: the suite's worker may
    # have begun the evaluation before the stop, and written its trace in the suite's storage.
    job = EvaluationJob.objects.get(pk=evaluation["id"])
    artifacts.save(model, artifacts.evaluation_prefix(job) + artifacts.EVALUATION_VIDEO, b"webm")
    video = client.get(f"{one}/files/video.webm", **token)
    assert video.status_code == 200 and video["Content-Type"] == "video/webm"
    assert b"".join(video.streaming_content) == b"webm"
    trace = client.get(f"{one}/files/evaluation-simtrace/0-iteration.csv", **token)
    assert trace.status_code == 404 and trace.json()["code"] == "not_found"  # not written
    assert client.get(f"{one}/files/video.webm", **api_token(bob, "read")).status_code == 404


@pytest.mark.slow  # the sandbox validates the clone's reward function
def test_a_clone_starts_from_its_sources_checkpoint_with_the_changes_given(
    alice, bob, tracks, client, own_storage
):  # own storage: it asks for a checkpoint no iteration saved, which another test's job may
    source = ready_model(alice)
    token = api_token(alice, "read", "train")
    body = {"name": "faster", "checkpoint": "last", "max_minutes": 12, "track": "rookie-loop"}
    cloned = client.post(
        f"{MODELS}/{source.pk}/clone", body, content_type="application/json", **token
    )
    assert cloned.status_code == 201, cloned.json()
    clone = RLModel.objects.get(name="faster")
    assert cloned.json()["cloned_from"] == source.pk and clone.cloned_from == source
    assert clone.cloned_checkpoint == "last" and clone.max_minutes == 12
    assert clone.track.name == "rookie-loop" and clone.action_space == source.action_space
    assert clone.network == source.network and clone.sensors == source.sensors
    others = client.post(
        f"{MODELS}/{source.pk}/clone",
        {"name": "x"},
        content_type="application/json",
        **api_token(bob, "train"),
    )
    assert others.status_code == 404
    fewer = client.post(
        f"{MODELS}/{source.pk}/clone",
        {"name": "fewer", "action_space": source.action_space[:1]},
        content_type="application/json",
        **token,
    )
    assert fewer.status_code == 400 and "action_space" in fewer.json()["errors"]
    nowhere = client.post(  # checked before the reward function runs (the fuzz's 503)
        f"{MODELS}/{source.pk}/clone",
        {"name": "x", "direction": "sideways"},
        "application/json",
        **token,
    )
    assert nowhere.status_code == 400 and "direction" in nowhere.json()["errors"]

    with_a_later_checkpoint(source, 3)  # iterations 1 and 3 kept: clone from the third's
    third = client.post(
        f"{MODELS}/{source.pk}/clone",
        {"name": "third", "checkpoint": 3},
        content_type="application/json",
        **token,
    )
    assert third.status_code == 201, third.json()
    clone = RLModel.objects.get(name="third")
    assert clone.cloned_checkpoint == "3"
    started = artifacts.read(artifacts.path(clone, artifacts.CLONED_WEIGHTS))
    assert started == artifacts.read(artifacts.path(source, artifacts.checkpoint(3)))
    client.force_login(alice)
    assert "the checkpoint of its iteration 3" in client.get(f"/models/{clone.pk}/").text
    client.logout()
    for missing in (2, 9):
        refused = client.post(
            f"{MODELS}/{source.pk}/clone",
            {"name": f"iteration-{missing}", "checkpoint": missing},
            content_type="application/json",
            **token,
        )
        assert refused.status_code == 400
        assert (
            f"no checkpoint of iteration {missing}" in refused.json()["errors"]["cloned_checkpoint"]
        )


@pytest.mark.slow  # builds the car's graph
def test_the_downloads_are_the_pages_archives_and_refusals_are_words(
    alice, bob, tracks, client, own_storage
):  # own storage: a model without traces, where another test's job may leave some
    model = ready_model(alice)
    token = api_token(alice, "read")
    physical = client.get(f"{MODELS}/{model.pk}/download/physical", **token)
    assert physical.status_code == 200 and physical["Content-Type"] == "application/gzip"
    with tarfile.open(fileobj=io.BytesIO(b"".join(physical.streaming_content))) as archive:
        assert sorted(archive.getnames()) == ["agent/model.pb", "model_metadata.json"]
    assert f"physicalmodel-{model.name}.tar.gz" in physical["Content-Disposition"]
    logs = client.get(f"{MODELS}/{model.pk}/download/logs", **token)  # made, not trained
    assert logs.status_code == 409 and logs.json()["message"] == logs_archive.NO_LOGS
    assert (
        client.get(f"{MODELS}/{model.pk}/download/physical", **api_token(bob, "read")).status_code
        == 404
    )
    assert client.get(f"{MODELS}/{model.pk}/download/floppy", **token).status_code == 400
    untrained = a_model(alice, "untrained")
    refused = client.get(f"{MODELS}/{untrained.pk}/download/physical", **token)
    assert refused.status_code == 409 and refused.json()["code"] == "refused"
