"""The `pitlane` command line against a running console (Daphne, a real token): a racer's
verbs as DeepRacer for Cloud's user types them, its tables, its --json and its refusals."""

from __future__ import annotations

import io
import json
import tarfile
from contextlib import redirect_stderr, redirect_stdout

import boto3
import pytest
import yaml
from pitlane_client import Client, cli

from accounts.tokens import token_create
from tests.helpers.archives import (
    DEEPRACER_HYPERPARAMETERS,
    DEEPRACER_METADATA,
    DEEPRACER_PARAMS,
    deepracer_export,
    drfc_layout,
)
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from tests.services import wait_for
from training.models import JobLogLine, RLModel
from training.rewards import EXAMPLES

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.slow]


def pitlane(*argv: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        code = cli.main(list(argv))
    return code, out.getvalue(), err.getvalue()


@pytest.fixture
def logged_in(alice, daphne_server, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.delenv("PITLANE_URL", raising=False)
    monkeypatch.delenv("PITLANE_TOKEN", raising=False)
    secret = token_create(owner=alice, name="cli", scopes=["read", "train", "race"], days=7)[1]
    code, out, _ = pitlane("login", "--url", daphne_server, "--token", secret)
    assert code == 0 and out.startswith(f"Logged in to {daphne_server} as alice (race, read")
    kept = tmp_path / "config" / "pitlane" / "config.json"
    assert kept.stat().st_mode & 0o777 == 0o600
    return secret


def test_a_racer_lists_shows_downloads_and_reads_a_leaderboard(
    alice, bob, tracks, logged_in, tmp_path
):
    model = ready_model(alice)
    code, out, _ = pitlane("models", "list")
    lines = out.splitlines()
    assert code == 0 and lines[0].split() == ["id", "name", "status", "track", "algorithm"]
    assert lines[1].split()[:3] == [str(model.pk), model.name, "READY"]
    code, out, _ = pitlane("--json", "models", "show", str(model.pk))
    assert code == 0 and json.loads(out)["name"] == model.name
    code, out, _ = pitlane("models", "show", str(model.pk))
    shown = dict(line.split(None, 1) for line in out.splitlines())
    assert shown["best_checkpoint_by"] == model.best_checkpoint_by
    assert shown["evaluation_trials"] == str(model.evaluation_trials)
    assert shown["direction"] == model.direction and shown["iterations"] == "1"

    code, out, err = pitlane("download", str(model.pk), "--physical", "--into", str(tmp_path))
    saved = tmp_path / f"physicalmodel-{model.name}.tar.gz"
    assert code == 0 and out.strip() == f"Saved {saved}" and "100%" in err
    with tarfile.open(saved) as archive:
        assert sorted(archive.getnames()) == ["agent/model.pb", "model_metadata.json"]

    JobLogLine.objects.create(job=model.jobs.get(), text="Iteration 1: reward 12.5")
    code, out, _ = pitlane("logs", str(model.pk), "--follow")  # the training ended: no wait
    assert code == 0 and out.strip().endswith("[trainer] Iteration 1: reward 12.5")

    race = event("Time trial", laps_required=1)
    scored(race, bob, 7_500, model_name="quicker")
    code, out, _ = pitlane("leaderboard", race.slug)
    assert code == 0 and out.splitlines()[1].split()[:3] == ["1", "bob", "quicker"]
    assert out.splitlines()[-1] == "page 1 of 1, 1 ranked"


def test_train_makes_a_model_from_a_deepracer_for_cloud_folder_and_refusals_are_words(
    alice, tracks, logged_in, tmp_path
):
    folder = tmp_path / "my-model"
    folder.mkdir()
    (folder / "model_metadata.json").write_text(json.dumps(DEEPRACER_METADATA))
    (folder / "hyperparameters.json").write_text(json.dumps(DEEPRACER_HYPERPARAMETERS))
    params = {**DEEPRACER_PARAMS, "WORLD_NAME": "Oval_track"}
    (folder / "training_params_1.yaml").write_text(yaml.safe_dump(params))
    (folder / "reward_function.py").write_text(EXAMPLES[0].source)
    code, _, err = pitlane("train", str(folder), "--name", "from-cli", "--minutes", "5")
    assert code == 1
    assert err == "pitlane: max_minutes: The maximum training time is 10 to 1440 minutes.\n"
    code, out, err = pitlane(
        "models", "create", str(folder), "--name", "from-cli", "--minutes", "10"
    )
    assert code == 0, err
    model = RLModel.objects.get(name="from-cli")
    assert out.startswith(f"Created from-cli (#{model.pk}); its training is queued.")
    assert model.track.name == "Oval_track" and model.max_minutes == 10

    code, _, err = pitlane("models", "delete", str(model.pk))  # it trains or waits to
    assert code == 1 and err.startswith("pitlane: The model is")
    code, out, _ = pitlane("models", "stop", str(model.pk))
    assert code == 0 and out.split(":")[0] in ("Canceled", "Stopping")

    code, _, err = pitlane("models", "show", "999999")
    assert code == 1 and err.strip() == "pitlane: No model of yours has the id 999999."
    code, _, err = pitlane("--json", "models", "list")
    assert code == 0


def test_a_token_that_does_not_work_is_told_plainly(daphne_server, tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path))
    code, _, err = pitlane("login", "--url", daphne_server, "--token", "plt_" + "x" * 40)
    assert code == 1 and err.startswith("pitlane: Send a working token")
    assert not (tmp_path / "pitlane" / "config.json").exists()
    monkeypatch.delenv("PITLANE_URL", raising=False)
    monkeypatch.delenv("PITLANE_TOKEN", raising=False)
    code, _, err = pitlane("models", "list")
    assert code == 1 and "not logged in" in err


def test_import_brings_a_model_from_a_deepracer_for_cloud_bucket_and_upload_a_folder(
    alice, tracks, logged_in, tmp_path, s3_server, monkeypatch
):
    """`pitlane import s3://bucket/prefix` reads the racer's own DeepRacer for Cloud bucket (its
    MinIO: --endpoint-url) with their keys, and the console previews the model it would train;
    --yes confirms it. `pitlane upload FOLDER` packs a folder; without --yes nothing is made."""
    for name, value in (("AWS_ACCESS_KEY_ID", "minio"), ("AWS_SECRET_ACCESS_KEY", "minio123")):
        monkeypatch.setenv(name, value)
    monkeypatch.setenv("AWS_DEFAULT_REGION", "us-east-1")
    s3 = boto3.client("s3", endpoint_url=s3_server)
    s3.create_bucket(Bucket="drfc")
    files = drfc_layout(deepracer_export())
    files["training_params.yaml"] = yaml.safe_dump({**DEEPRACER_PARAMS, "WORLD_NAME": "Oval_track"})
    for path, data in files.items():
        s3.put_object(Bucket="drfc", Key=f"rl-deepracer-sagemaker/{path}", Body=data)

    source = "s3://drfc/rl-deepracer-sagemaker"
    code, out, err = pitlane(
        "import", source, "--endpoint-url", s3_server, "--name", "from-bucket", "--yes"
    )
    assert code == 0, err
    model = RLModel.objects.get(name="from-bucket")
    assert "would train on Oval_track (counterclockwise)" in out
    assert f"Imported from-bucket (#{model.pk})" in out and "100%" in err
    code, _, err = pitlane("import", "s3://drfc/missing", "--endpoint-url", s3_server)
    assert code == 1 and err.startswith("pitlane: Nothing is stored under s3://drfc/missing")

    folder = tmp_path / "folder"
    folder.mkdir()
    for name, data in deepracer_export().items():
        (folder / name).write_bytes(data if isinstance(data, bytes) else data.encode())
    code, out, err = pitlane("upload", str(folder), "--name", "from-folder")
    assert code == 1 and "Not imported: nothing was created." in err
    assert not RLModel.objects.filter(name="from-folder").exists()


def test_a_racers_whole_day_through_the_command_line(
    alice, tracks, logged_in, tmp_path, celery_worker_process, daphne_server
):
    """Validate, train a tiny model from a DeepRacer for Cloud folder and wait for its first
    iteration, stop it, evaluate it, download the car's archive, race it and read the board:
    every step a verb, against a running console and its workers."""
    assert Client(daphne_server, logged_in).validate(EXAMPLES[0].source)["valid"] is True
    folder = tmp_path / "tiny"
    folder.mkdir()
    # Straight ahead whatever it learns, at 3.5 or 4 m/s: off at each bend and put back, so its
    # evaluation and race finish their laps in a few seconds, as a young model's would not.
    straight = [
        {"steering_angle": 0.0, "speed": speed, "index": n} for n, speed in enumerate((3.5, 4.0))
    ]
    (folder / "model_metadata.json").write_text(
        json.dumps({**DEEPRACER_METADATA, "action_space": straight})
    )
    tiny = {**DEEPRACER_HYPERPARAMETERS, "batch_size": 32, "num_epochs": 3}
    (folder / "hyperparameters.json").write_text(
        json.dumps({**tiny, "num_episodes_between_training": 5})
    )
    params = {**DEEPRACER_PARAMS, "WORLD_NAME": "Oval_track"}
    (folder / "training_params.yaml").write_text(yaml.safe_dump(params))
    (folder / "reward_function.py").write_text(EXAMPLES[0].source)
    code, out, err = pitlane("train", str(folder), "--name", "day-one", "--minutes", "10", "--wait")
    assert code == 0, err
    assert "waiting for the first iteration" in err  # the wait, shown as it goes
    model = RLModel.objects.get(name="day-one")
    assert model.jobs.get().iterations >= 1

    assert pitlane("models", "stop", str(model.pk))[0] == 0
    wait_for(lambda: RLModel.objects.get(pk=model.pk).status == "READY", "the model saved", 120)
    code, out, err = pitlane("evaluate", str(model.pk), "--max-resets", "0", "--wait")
    assert code == 0 and "COMPLETED" in out.splitlines()[0], (out, err)

    code, out, _ = pitlane("download", str(model.pk), "--physical", "--into", str(tmp_path))
    with tarfile.open(tmp_path / "physicalmodel-day-one.tar.gz") as archive:
        assert sorted(archive.getnames()) == ["agent/model.pb", "model_metadata.json"]

    race = event("Day race", laps_required=1, laps_to_drive=1)
    code, out, err = pitlane("submit", str(model.pk), race.slug)
    assert code == 0 and "is on the grid for day-race" in out, err
    wait_for(
        lambda: race.submissions.filter(status__in=("COMPLETED", "FAILED")).exists(),
        "the race to be scored",
        180,
    )
    code, out, _ = pitlane("runs")
    assert code == 0 and "day-one" in out
    code, out, _ = pitlane("leaderboard", race.slug)
    assert code == 0 and out.splitlines()[-1].startswith("page 1 of")
