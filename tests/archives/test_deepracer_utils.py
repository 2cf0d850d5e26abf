"""The logs archive and the files in it, read by deepracer-utils as the community's log-analysis
notebooks read a DeepRacer model folder: ``DeepRacerLog(folder)`` and
``AnalysisUtils.simulation_agg`` for the simulation traces, ``TrainingMetrics`` for the metrics.

Every number it reads back is checked against what the job recorded: the iterations' rows and
their per-episode points, the evaluation's trials. ``assert_training_logs_read_as_recorded`` and
``assert_evaluation_logs_read_as_recorded`` (tests/helpers/training_logs.py) are also called by the
end-to-end training test and the evaluate-command test, on a real job's files."""

from __future__ import annotations

import io
import json
import math
import tarfile
import tempfile
from pathlib import Path

import pytest
from deepracer.logs import DeepRacerLog
from django.core.management import CommandError, call_command
from django.urls import reverse

from archives import history
from jobs import trainer
from tests.helpers.training_logs import (
    EPISODES,
    assert_training_logs_read_as_recorded,
    extracted,
    new_model,
    train_on_paper,
)
from training import artifacts
from training.models import Iteration

EPISODE_KEYS = {
    "reward_score",
    "metric_time",
    "start_time",
    "elapsed_time_in_milliseconds",
    "episode",
    "trial",
    "phase",
    "completion_percentage",
    "episode_status",
}


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
@pytest.mark.django_db
def test_deepracer_utils_reads_the_training_logs_as_the_job_recorded_them(alice, tracks):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    points = [p for row in Iteration.objects.filter(job__model=model) for p in row.training_points]
    assert {progress >= 100 for _, progress in points} == {True, False}  # laps and off-tracks
    assert_training_logs_read_as_recorded(model)


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
@pytest.mark.django_db
def test_the_training_metrics_are_deepracers_and_read_back_as_a_history(alice, tracks):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    stored = artifacts.read(artifacts.path(model, artifacts.TRAINING_METRICS))
    document = json.loads(stored)
    assert (document["version"], document["best_model_metric"]) == (2.0, "progress")
    entries = document["metrics"]
    assert all(set(entry) == EPISODE_KEYS for entry in entries)
    assert all(isinstance(entry["reward_score"], int) for entry in entries)
    assert [(e["phase"], e["episode"], e["trial"]) for e in entries] == [
        ("training", 1, 1),
        ("training", 2, 2),
        ("training", 3, 3),
        ("training", 4, 4),
        ("evaluation", 4, 4),
        ("evaluation", 4, 4),
        ("training", 5, 1),
        ("training", 6, 2),
        ("training", 7, 3),
        ("training", 8, 4),
        ("evaluation", 8, 4),
        ("evaluation", 8, 4),
    ]
    labels = {entry["episode_status"] for entry in entries}
    assert "Lap complete" in labels and labels <= set(artifacts.STATUS_LABELS.values())
    # An imported model's page reads it back: the same iterations, episodes and laps.
    found = history.read(stored, episodes_per_iteration=EPISODES)
    assert [row.episodes for row in found.iterations] == [EPISODES, EPISODES]
    assert [row.evaluation_completion for row in found.iterations] == [100.0, 100.0]


def test_evaluation_entries_follow_the_iteration_they_evaluate_even_when_they_come_late():
    def entry(phase: str, episode: int, trial: int) -> dict:
        return {"phase": phase, "episode": episode, "trial": trial}

    metrics = [entry("training", n, (n - 1) % 2 + 1) for n in range(1, 5)]
    late = trainer.with_evaluation(metrics, [entry("evaluation", 0, 0)], episodes=2)
    assert [(e["phase"], e["episode"], e["trial"]) for e in late] == [
        ("training", 1, 1),
        ("training", 2, 2),
        ("evaluation", 2, 2),
        ("training", 3, 1),
        ("training", 4, 2),
    ]


def test_training_traces_are_named_from_iteration_zero_as_deepracers():
    assert artifacts.training_trace(1) == "training-simtrace/0-iteration.csv"
    assert artifacts.status_label("time_up") == "Time Up"
    assert artifacts.status_label("off_track") == "Off track"


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
@pytest.mark.django_db
def test_the_logs_archive_is_a_deepracer_model_folder(alice, tracks, client):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    client.force_login(alice)
    response = client.get(reverse("archives:model-logs", args=[model.pk]))
    assert response.status_code == 200
    assert response["Content-Disposition"].startswith("attachment")
    assert "logs-paper-trained.tar.gz" in response["Content-Disposition"]
    data = b"".join(response.streaming_content)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
        names = set(archive.getnames())
    assert names == {
        f"paper-trained/{name}"
        for name in (
            "model/model_metadata.json",
            "ip/hyperparameters.json",
            "reward_function.py",
            "training_params.yaml",
            "training-simtrace/0-iteration.csv",
            "training-simtrace/1-iteration.csv",
            "metrics/TrainingMetrics.json",
            "logs/training-log.txt",
        )
    }
    with tempfile.TemporaryDirectory() as directory:
        folder = extracted(model, Path(directory))
        log = DeepRacerLog(str(folder))
        log.load_training_trace()  # with the model's metadata: no warning about it
        assert log.action_space() is not None
        assert "Training log of paper-trained" in (folder / "logs/training-log.txt").read_text()


@pytest.mark.django_db
def test_only_the_models_owner_downloads_its_logs(alice, bob, tracks, client):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    client.force_login(bob)
    assert client.get(reverse("archives:model-logs", args=[model.pk])).status_code == 404
    client.logout()
    response = client.get(reverse("archives:model-logs", args=[model.pk]))
    assert response.status_code == 302 and "login" in response["Location"]


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
@pytest.mark.django_db
def test_a_model_with_no_logs_yet_says_so(alice, tracks, client, tmp_path):
    model = new_model(alice, "untrained")
    client.force_login(alice)
    response = client.get(reverse("archives:model-logs", args=[model.pk]), follow=True)
    assert "no logs yet" in response.content.decode()
    with pytest.raises(CommandError, match="no logs yet"):
        call_command("exportmodel", "untrained", "--logs", "-o", str(tmp_path))
    assert not list(tmp_path.iterdir())


@pytest.mark.django_db
def test_exportmodel_writes_the_logs_archive(alice, tracks, tmp_path, capsys):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    call_command("exportmodel", "paper-trained", "--logs", "-o", str(tmp_path))
    written = tmp_path / "logs-paper-trained.tar.gz"
    assert f"Wrote {written}" in capsys.readouterr().out
    with tarfile.open(written, mode="r:gz") as archive:
        archive.extractall(tmp_path / "out", filter="data")
    log = DeepRacerLog(str(tmp_path / "out/paper-trained"))
    log.load_training_trace()
    assert not math.isnan(log.dataframe()["unique_episode"].max())
