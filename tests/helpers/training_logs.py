"""A job's logs, read back by deepracer-utils as the community's log-analysis notebooks read a
DeepRacer model folder and checked against what the job recorded; and logs recorded on paper, as
the trainer records them with no learning."""

from __future__ import annotations

import io
import json
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

import simulator
from archives import logs_archive
from jobs import trainer
from rl.experience import Episode
from simulator.controller import CentreLineDriver
from tests.helpers.models import trained_model
from training import artifacts
from training.models import EvaluationJob, Iteration, RLModel

STEP = 1 / 15  # [s]
EVALUATION_KEYS = {
    "completion_percentage",
    "metric_time",
    "start_time",
    "elapsed_time_in_milliseconds",
    "episode_status",
    "crash_count",
    "immobilized_count",
    "off_track_count",
    "reversed_count",
    "reset_count",
    "trial",
}


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
        worker=seed % 2,
        version=0,
        observations={},
        actions=np.zeros(len(rewards)),
        rewards=np.array(rewards, dtype=np.float32),
        values=None,
        log_probs=None,
        terminated=terminated,
        final_value=0.0,
        progress=info["progress"],
        status=info["status"],
        lap_time=None,
        trace=trace,
    )


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
            metrics,
            trainer.evaluation_metrics(evaluation, now=1_700_000_100.0),
            episodes=number * EPISODES,
        )
        Iteration.objects.create(
            job=job,
            number=number,
            reward=0.0,
            completion=0.0,
            episodes=EPISODES,
            steps=sum(e.steps for e in episodes),
            wall_seconds=1.0,
            training_points=[
                [round(float(e.rewards.sum()), 3), round(e.progress, 2)] for e in episodes
            ],
            evaluation_points=[100.0, 100.0],
        )
    env.close()
    artifacts.save(model, artifacts.TRAINING_METRICS, trainer.metrics_document(metrics))
