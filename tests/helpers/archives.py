"""Archives as racers upload them: DeepRacer exports (in DeepRacer's and DeepRacer for Cloud's
layouts), Pitlane's virtual models with their training history, and physical-car archives."""

from __future__ import annotations

import io
import json
import tarfile

import pytest
import yaml

from archives import exports
from tests.helpers.models import ready_model
from training import artifacts
from training.models import RLModel, TrainingJob
from training.rewards import EXAMPLES

DEEPRACER_METADATA = {
    "action_space": [
        {"steering_angle": -30.0, "speed": 0.6, "index": 0},
        {"steering_angle": 0.0, "speed": 1.2, "index": 1},
        {"steering_angle": 30.0, "speed": 0.6, "index": 2},
    ],
    "sensor": ["FRONT_FACING_CAMERA"],
    "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
    "version": "4",
    "training_algorithm": "clipped_ppo",
    "action_space_type": "discrete",
}
DEEPRACER_HYPERPARAMETERS = {
    "batch_size": 64,
    "beta_entropy": 0.01,
    "discount_factor": 0.999,
    "e_greedy_value": 0.05,
    "epsilon_steps": 10000,
    "exploration_type": "categorical",
    "loss_type": "huber",
    "lr": 0.0003,
    "num_episodes_between_training": 20,
    "num_epochs": 10,
    "stack_size": 1,
    "term_cond_avg_score": 350.0,
    "term_cond_max_episodes": 1000,
}

# H_track: a DeepRacer world (deepracer-utils' track_meta names it) whose route simapp does not
# ship, so it is not one of the built-in tracks: the archive's track is not loaded here.
DEEPRACER_PARAMS = {
    "WORLD_NAME": "H_track",
    "REVERSE_DIR": False,
    "RACE_TYPE": "TIME_TRIAL",
    "CAR_NAME": "my-deepracer-car",
}

# The import page hands the archive to a checker thread (training.checkers), which writes with a
# database connection of its own: what the test made must be committed for it to see.
CHECKED_IMPORT = pytest.mark.django_db(transaction=True)


def tar_gz(members: dict[str, bytes], tweak=None) -> bytes:
    """A .tar.gz of ``members``; ``tweak(tar)`` may add hostile entries."""
    buffer = io.BytesIO()
    with tarfile.open(fileobj=buffer, mode="w:gz", compresslevel=1) as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
        if tweak:
            tweak(tar)
    return buffer.getvalue()


def deepracer_export(**changes) -> dict[str, bytes]:
    """A DeepRacer model's files (no weights), with ``changes`` over them."""
    members = {
        "model_metadata.json": json.dumps(DEEPRACER_METADATA).encode(),
        "reward_function.py": EXAMPLES[0].source.encode(),
        "hyperparameters.json": json.dumps(DEEPRACER_HYPERPARAMETERS).encode(),
        "training_params.yaml": yaml.safe_dump(DEEPRACER_PARAMS).encode(),
    }
    return {**members, **changes}


def drfc_layout(members: dict[str, bytes]) -> dict[str, bytes]:
    """The files as DeepRacer for Cloud uploads a model: the metadata under model/ (and at the
    root), the hyperparameters under ip/."""
    moved = dict(members)
    moved["model/model_metadata.json"] = moved["model_metadata.json"]
    moved["ip/hyperparameters.json"] = moved.pop("hyperparameters.json")
    return moved


def deepracer_folder(**params) -> bytes:
    """A DeepRacer model folder without weights: its reward function and settings."""
    return tar_gz(
        deepracer_export(
            **{
                "training_params.yaml": yaml.safe_dump({**DEEPRACER_PARAMS, **params}).encode(),
            }
        )
    )


def virtual_archive(model: RLModel) -> bytes:
    """``model``'s virtual-model archive, as the racer downloads it."""
    with artifacts.default_storage.open(exports.virtual(model).name, "rb") as file:
        return file.read()


def trainer_metrics(iterations: int = 2, episodes: int = 3) -> dict:
    """training_metrics.json as our trainer writes it: each iteration's training episodes
    (trial 1, 2, ...), then the evaluation of the policy learnt from them."""
    rows, episode, clock = [], 0, 1_700_000_000_000
    for number in range(1, iterations + 1):
        for trial in range(1, episodes + 1):
            episode += 1
            lap = number == iterations and trial == episodes
            rows.append(
                {
                    "reward_score": 10.0 * number + trial,
                    "metric_time": clock + 4000,
                    "start_time": clock,
                    "elapsed_time_in_milliseconds": 4000 if lap else 2000,
                    "episode": episode,
                    "trial": trial,
                    "phase": "training",
                    "completion_percentage": 100 if lap else 20 * number,
                    "episode_status": "lap_complete" if lap else "off_track",
                }
            )
            clock += 5000
        for trial in (1, 2):
            rows.append(
                {
                    "reward_score": 0,
                    "metric_time": clock + 1000,
                    "start_time": clock,
                    "elapsed_time_in_milliseconds": 1000,
                    "episode": episode,
                    "trial": trial,
                    "phase": "evaluation",
                    "completion_percentage": 30 * number + 10 * trial,
                    "episode_status": "off_track",
                }
            )
            clock += 1000
    return {"metrics": rows, "best_model_metric": "progress"}


def trained_with_history(owner) -> RLModel:
    """A ready model with two iterations of ``trainer_metrics``' history, trained 150.4 s."""
    model = ready_model(owner)
    artifacts.save(model, artifacts.TRAINING_METRICS, json.dumps(trainer_metrics()))
    TrainingJob.objects.filter(model=model).update(training_seconds=150.4, iterations=2)
    return model


def car_archive(owner) -> bytes:
    """A physical-car archive (model_metadata.json and agent/model.pb), as the car takes it."""
    with artifacts.default_storage.open(exports.physical(ready_model(owner)).name, "rb") as file:
        return file.read()
