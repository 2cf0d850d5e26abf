"""The logs archive and the files in it, read by deepracer-utils as the community's log-analysis
notebooks read a DeepRacer model folder: ``DeepRacerLog(folder)`` and
``AnalysisUtils.simulation_agg`` for the simulation traces, ``TrainingMetrics`` for the metrics.

Every number it reads back is checked against what the job recorded: the iterations' rows and
their per-episode points, the evaluation's trials. ``assert_training_logs_read_as_recorded`` and
``assert_evaluation_logs_read_as_recorded`` are also called by the end-to-end training test and
the evaluate-command test, on a real job's files."""

from __future__ import annotations

import io
import json
import math
import shutil
import tarfile
import tempfile
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from deepracer.logs import AnalysisUtils, DeepRacerLog, TrainingMetrics
from deepracer.logs.misc import LogFolderType
from django.conf import settings
from django.core.management import CommandError, call_command
from django.urls import reverse

import simulator
from rl.experience import Episode
from simulator.controller import CentreLineDriver
from tests.training.factories import trained_model
from training import artifacts, history, logs_archive, trainer
from training.models import EvaluationJob, Iteration, RLModel

STEP = 1 / 15  # [s]
EPISODE_KEYS = {
    "reward_score", "metric_time", "start_time", "elapsed_time_in_milliseconds", "episode",
    "trial", "phase", "completion_percentage", "episode_status",
}  # fmt: skip
EVALUATION_KEYS = {
    "completion_percentage", "metric_time", "start_time", "elapsed_time_in_milliseconds",
    "episode_status", "crash_count", "immobilized_count", "off_track_count", "reversed_count",
    "reset_count", "trial",
}  # fmt: skip


def extracted(model: RLModel, into: Path) -> Path:
    """The model's logs archive, as the racer downloads it, extracted into ``into``: the model
    folder."""
    data = io.BytesIO()
    logs_archive.write(model, data)
    data.seek(0)
    with tarfile.open(fileobj=data, mode="r:gz") as archive:
        archive.extractall(into, filter="data")
    (folder,) = into.iterdir()
    return folder


def assert_training_logs_read_as_recorded(model: RLModel) -> None:
    """deepracer-utils reads the model's training logs as its job recorded them: per iteration,
    its episodes with their steps, times, progress, rewards and completed laps."""
    recorded = list(Iteration.objects.filter(job__model=model).order_by("number"))
    assert recorded, "the model has no iteration to read"
    with tempfile.TemporaryDirectory() as directory:
        folder = extracted(model, Path(directory))
        log = DeepRacerLog(str(folder))
        assert log.fh.type == LogFolderType.DRFC_MODEL_SINGLE_WORKERS
        log.load_training_trace()
        trace = log.dataframe()
        metrics = TrainingMetrics(None, fname=str(folder / "metrics/TrainingMetrics.json"))
    assert trace["unique_episode"].notna().all()  # it found iteration 0 and numbered every row
    agg = AnalysisUtils.simulation_agg(trace.copy(), secondgroup="unique_episode")
    assert len(agg) == sum(row.episodes for row in recorded)  # no two episodes merged
    assert (agg["time"] >= 0).all()
    # A prepare row (step 1) begins each episode: its time is its steps after that one.
    assert np.allclose(agg["time"], (agg["steps"] - 1) * STEP, atol=1e-3)

    training = metrics.metrics[metrics.metrics["phase"] == "training"]
    assert len(training) == len(agg)
    assert training["time"].to_numpy() == pytest.approx(agg["time"].to_numpy(), abs=2e-3)
    for row in recorded:
        episodes = agg[agg["iteration"] == row.number - 1].sort_values("unique_episode")
        entries = training[training["iteration"] == row.number - 1]
        assert len(episodes) == len(entries) == row.episodes
        assert list(entries["trial"]) == list(range(1, row.episodes + 1))
        assert int((episodes["steps"] - 1).sum()) == row.steps
        for (reward, progress), (_, episode), (_, entry) in zip(
            row.training_points, episodes.iterrows(), entries.iterrows(), strict=True
        ):
            assert episode["reward"] == pytest.approx(reward, abs=0.01 * episode["steps"])
            assert episode["progress"] >= progress - 0.01  # the most it reached, its last
            assert abs(entry["completion"] - progress) <= 1
            assert abs(entry["reward"] - reward) <= 1
        laps = sum(progress >= 100 for _, progress in row.training_points)
        assert episodes["complete"].sum() == entries["complete"].sum() == laps
    evaluations = metrics.metrics[metrics.metrics["phase"] == "evaluation"]
    evaluated = {row.number - 1: len(row.evaluation_points) for row in recorded}
    for iteration, count in evaluations.groupby("iteration").size().items():
        assert count == evaluated[iteration]  # each evaluation is in the iteration it followed


def assert_evaluation_logs_read_as_recorded(evaluation: EvaluationJob) -> None:
    """deepracer-utils reads the evaluation in the model's logs as it was recorded: one episode
    per trial, with its time, progress and lap; its metrics file is DeepRacer's."""
    trials = list(evaluation.trial_rows.order_by("number"))
    with tempfile.TemporaryDirectory() as directory:
        folder = extracted(evaluation.model, Path(directory))
        log = DeepRacerLog(str(folder))
        log.load_evaluation_trace()
        trace = log.dataframe()
        (stream,) = trace["stream"].unique()
        assert len(stream) == 14
        document = json.loads((folder / f"metrics/EvaluationMetrics-{stream}.json").read_text())
    agg = AnalysisUtils.simulation_agg(trace.copy(), firstgroup="stream", is_eval=True)
    assert len(agg) == len(trials)
    assert (agg["time"] >= 0).all()
    assert np.allclose(agg["time"], (agg["steps"] - 1) * STEP, atol=1e-3)
    for (_, episode), trial in zip(agg.sort_values("episode").iterrows(), trials, strict=True):
        assert episode["progress"] == pytest.approx(trial.progress, abs=0.01)
        assert episode["complete"] == (trial.status == "lap_complete")
        assert episode["time"] == pytest.approx(trial.time_ms / 1000, abs=STEP + 1e-3)
    entries = document["metrics"]
    assert [entry["trial"] for entry in entries] == [trial.number for trial in trials]
    assert all(set(entry) == EVALUATION_KEYS for entry in entries)
    assert [entry["episode_status"] for entry in entries] == [
        artifacts.status_label(trial.status) for trial in trials
    ]


# A training job's files, written by the trainer's own functions from episodes driven in the
# simulator: two iterations of four episodes, each followed by an evaluation.

EPISODES = 4


def new_model(owner, name: str) -> RLModel:
    """A trained model with no logs: none either of an earlier test's model that had its number
    (the test database hands numbers out again; storage outlives its rows)."""
    model = trained_model(owner, name)
    for folder in ("training-simtrace", "metrics", "evaluations"):
        shutil.rmtree(settings.MEDIA_ROOT / "models" / str(model.pk) / folder, ignore_errors=True)
    return model


STRAIGHT_AHEAD = 7  # 0° at 1 m/s in DeepRacer's default action space: off at the first bend


def drive(env, seed: int) -> Episode:
    """One episode as a rollout worker drives it: the prepare row, then a row per step. An even
    ``seed`` follows the centre line round a lap, an odd one goes straight off the track."""
    _, info = env.reset(seed=seed)
    driver = CentreLineDriver(env.unwrapped) if seed % 2 == 0 else None
    trace, rewards = [list(info["trace"])], []
    while True:
        action = driver.act() if driver else STRAIGHT_AHEAD
        _, reward, terminated, truncated, info = env.step(action)
        trace.append(list(info["trace"]))
        rewards.append(reward)
        if terminated or truncated:
            break
    return Episode(
        worker=seed % 2, version=0, observations={}, actions=np.zeros(len(rewards)),
        rewards=np.array(rewards, dtype=np.float32), values=None, log_probs=None,
        terminated=terminated, final_value=0.0, progress=info["progress"],
        status=info["status"], lap_time=None, trace=trace,
    )  # fmt: skip


def train_on_paper(model: RLModel) -> None:
    """Record two iterations of the model's job as the trainer does, with no learning."""
    job = model.jobs.get()
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
    metrics: list[dict] = []
    Iteration.objects.filter(job=job).delete()
    for number in (1, 2):
        episodes = [drive(env, seed) for seed in range(EPISODES * number, EPISODES * (number + 1))]
        before = (number - 1) * EPISODES
        metrics += trainer.training_metrics(episodes, before=before, now=1_700_000_000.0)
        artifacts.save(
            model, artifacts.training_trace(number), trainer.training_trace(episodes, before=before)
        )
        evaluation = [{"progress": 100.0, "status": "lap_complete", "steps": 150}] * 2
        metrics = trainer.with_evaluation(
            metrics, trainer.evaluation_metrics(evaluation, now=1_700_000_100.0),
            episodes=number * EPISODES,
        )  # fmt: skip
        Iteration.objects.create(
            job=job, number=number, reward=0.0, completion=0.0, episodes=EPISODES,
            steps=sum(e.steps for e in episodes), wall_seconds=1.0,
            training_points=[[round(float(e.rewards.sum()), 3), round(e.progress, 2)]
                             for e in episodes],
            evaluation_points=[100.0, 100.0],
        )  # fmt: skip
    env.close()
    artifacts.save(model, artifacts.TRAINING_METRICS, trainer.metrics_document(metrics))


@pytest.mark.django_db
def test_deepracer_utils_reads_the_training_logs_as_the_job_recorded_them(alice, tracks):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    points = [p for row in Iteration.objects.filter(job__model=model) for p in row.training_points]
    assert {progress >= 100 for _, progress in points} == {True, False}  # laps and off-tracks
    assert_training_logs_read_as_recorded(model)


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
        ("training", 1, 1), ("training", 2, 2), ("training", 3, 3), ("training", 4, 4),
        ("evaluation", 4, 4), ("evaluation", 4, 4),
        ("training", 5, 1), ("training", 6, 2), ("training", 7, 3), ("training", 8, 4),
        ("evaluation", 8, 4), ("evaluation", 8, 4),
    ]  # fmt: skip
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
        ("training", 1, 1), ("training", 2, 2), ("evaluation", 2, 2),
        ("training", 3, 1), ("training", 4, 2),
    ]  # fmt: skip


def test_training_traces_are_named_from_iteration_zero_as_deepracers():
    assert artifacts.training_trace(1) == "training-simtrace/0-iteration.csv"
    assert artifacts.status_label("time_up") == "Time Up"
    assert artifacts.status_label("off_track") == "Off track"


@pytest.mark.django_db
def test_the_logs_archive_is_a_deepracer_model_folder(alice, tracks, client):
    model = new_model(alice, "paper-trained")
    train_on_paper(model)
    client.force_login(alice)
    response = client.get(reverse("training:model-logs", args=[model.pk]))
    assert response.status_code == 200
    assert response["Content-Disposition"].startswith("attachment")
    assert "logs-paper-trained.tar.gz" in response["Content-Disposition"]
    data = b"".join(response.streaming_content)
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
        names = set(archive.getnames())
    assert names == {
        f"paper-trained/{name}"
        for name in (
            "model/model_metadata.json", "ip/hyperparameters.json", "reward_function.py",
            "training_params.yaml", "training-simtrace/0-iteration.csv",
            "training-simtrace/1-iteration.csv", "metrics/TrainingMetrics.json",
            "logs/training-log.txt",
        )
    }  # fmt: skip
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
    assert client.get(reverse("training:model-logs", args=[model.pk])).status_code == 404
    client.logout()
    response = client.get(reverse("training:model-logs", args=[model.pk]))
    assert response.status_code == 302 and "login" in response["Location"]


@pytest.mark.django_db
def test_a_model_with_no_logs_yet_says_so(alice, tracks, client, tmp_path):
    model = new_model(alice, "untrained")
    client.force_login(alice)
    response = client.get(reverse("training:model-logs", args=[model.pk]), follow=True)
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
