"""A model's files in storage (local disk or S3, through Django's storage API), under one prefix:
``models/<id>/``, laid out as DeepRacer lays out a model."""

from __future__ import annotations

import json

import yaml
from django.core.files.base import ContentFile
from django.core.files.storage import default_storage

from training.models import RLModel


def path(model: RLModel, relative: str) -> str:
    return f"models/{model.pk}/{relative}"


def save(model: RLModel, relative: str, data: bytes | str) -> str:
    """Write ``data`` at ``relative`` under the model's prefix, replacing what was there."""
    name = path(model, relative)
    if default_storage.exists(name):
        default_storage.delete(name)
    content = data.encode() if isinstance(data, str) else data
    return default_storage.save(name, ContentFile(content))


def read(name: str) -> bytes:
    with default_storage.open(name, "rb") as file:
        return file.read()


def write_model_files(model: RLModel) -> None:
    """DeepRacer's description of a model: its metadata, reward function and settings."""
    save(model, "model_metadata.json", json.dumps(model.metadata(), indent=2))
    save(model, "reward_function.py", model.reward_function)
    save(model, "hyperparameters.json", json.dumps(model.hyperparameters, indent=2))
    save(model, "training_params.yaml", yaml.safe_dump(training_params(model), sort_keys=True))


def training_params(model: RLModel) -> dict:
    """The environment side of the configuration, as DeepRacer's training_params.yaml names it."""
    params = {
        "WORLD_NAME": model.track.name,
        "REVERSE_DIR": model.direction == "clockwise",
        "RACE_TYPE": model.race_type,
        "ALTERNATE_DRIVING_DIRECTION": False,
        "CHANGE_START_POSITION": True,
        "NUMBER_OF_RESETS": 0,
        "JOB_TYPE": "TRAINING",
        "MAX_TRAINING_TIME_MINUTES": model.max_minutes,
        "NUM_WORKERS": model.workers,
        "MULTI_TRACK": [model.track.name, *model.extra_tracks],
        "CAR_NAME": model.name,
    }
    if model.boxes:
        params["NUMBER_OF_OBSTACLES"] = model.boxes.get("count", 3)
        params["RANDOMIZE_OBSTACLE_LOCATIONS"] = bool(model.boxes.get("randomize"))
    if model.bots:
        params["NUMBER_OF_BOT_CARS"] = model.bots.get("count", 3)
        params["BOT_CAR_SPEED"] = model.bots.get("speed", 0.5)
        params["IS_LANE_CHANGE"] = bool(model.bots.get("lane_changes"))
    return params
