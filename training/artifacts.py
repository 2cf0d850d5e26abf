"""A model's files in storage (local disk or S3, through Django's storage API), under one prefix:
``models/<id>/``, laid out as DeepRacer lays out a model."""

from __future__ import annotations

import json
import re

import yaml
from django.core.files.base import ContentFile
from django.core.files.storage import FileSystemStorage, default_storage
from django.http import HttpRequest, HttpResponse, HttpResponseRedirect

from common.downloads import file_response
from common.transactions import outside_transaction
from rl.hyperparameters import deepracer_json
from simulator import tracks as sim_tracks
from training.models import EvaluationJob, RLModel

TRAINING_METRICS = "metrics/training_metrics.json"  # DeepRacer's (docs/coming-from-deepracer.md)
CLONED_WEIGHTS = "checkpoints/cloned.safetensors"  # a clone's start: its source's best weights
# Where a virtual model's archive keeps its best and last checkpoints (archives.exports), and an
# import finds them (archives.imports).
EXPORTED_CHECKPOINTS = {
    "best": "checkpoints/best.safetensors",
    "last": "checkpoints/last.safetensors",
}
# An evaluation's files, under ``evaluation_prefix``.
EVALUATION_VIDEO = "video.webm"
EVALUATION_TRACE = "evaluation-simtrace/0-iteration.csv"
EVALUATION_METRICS = "metrics/evaluation_metrics.json"


# simapp bundle/markov/metrics/constants.py:118-129 (01f5f01): the labels the metrics JSON gives
# an episode's status (the simulation trace keeps the names on the left)
STATUS_LABELS = {
    "lap_complete": "Lap complete",
    "crashed": "Crashed",
    "off_track": "Off track",
    "immobilized": "Immobilized",
    "in_progress": "In progress",
    "pause": "Pause",
    "reversed": "Reversed",
    "park": "Park",
    "time_up": "Time Up",
    "prepare": "Prepare",
}


def status_label(status: str) -> str:
    """An episode status as DeepRacer's metrics JSON writes it ("Lap complete", "Off track")."""
    return STATUS_LABELS.get(status, status.replace("_", " ").capitalize())


def training_trace(number: int) -> str:
    """The simulation trace of iteration ``number`` (1, 2, ... as pages count them), named as
    DeepRacer names it: its uploads count from 0, so iteration 1 is ``0-iteration.csv``
    (simapp bundle/markov/boto/s3/files/simtrace_video.py:50-54, 70, 77 (01f5f01))."""
    return f"training-simtrace/{number - 1}-iteration.csv"


def checkpoint(number: int) -> str:
    """Where the trainer keeps the weights of iteration ``number`` (0: the weights it started
    from), relative to the model's prefix."""
    return f"checkpoints/iteration-{number}.safetensors"


def checkpoint_iteration(name: str) -> int | None:
    """The iteration whose weights the stored checkpoint ``name`` holds; None for weights that
    came otherwise (an import)."""
    found = re.search(r"/checkpoints/iteration-(\d+)\.safetensors$", name)
    return int(found.group(1)) if found else None


def evaluation_prefix(evaluation: EvaluationJob) -> str:
    """Where an evaluation's files live, relative to its model's prefix."""
    return f"evaluations/{evaluation.pk}/"


def path(model: RLModel, relative: str) -> str:
    return f"models/{model.pk}/{relative}"


def save(model: RLModel, relative: str, data: bytes | str) -> str:
    """Write ``data`` at ``relative`` under the model's prefix, replacing what was there; never
    inside a transaction (a checkpoint may be hundreds of MiB, to a bucket)."""
    outside_transaction("A file written to storage")
    name = path(model, relative)
    if default_storage.exists(name):
        default_storage.delete(name)
    content = data.encode() if isinstance(data, str) else data
    return default_storage.save(name, ContentFile(content))


def read(name: str) -> bytes:
    with default_storage.open(name, "rb") as file:
        return file.read()


def download(
    request: HttpRequest,
    name: str,
    filename: str,
    *,
    attachment: bool = True,
    content_type: str | None = None,
) -> HttpResponse:
    """The stored file ``name`` for a racer whose right to it the caller has checked: streamed
    from local storage, the byte range asked for if one is (``common.downloads``: a video seeks
    so), or a redirect to a presigned URL that expires in minutes from a bucket (the bytes then
    never pass through the web server, and S3 answers the range itself)."""
    if isinstance(default_storage, FileSystemStorage):
        return file_response(
            request,
            default_storage.open(name, "rb"),
            filename=filename,
            attachment=attachment,
            content_type=content_type,
        )
    disposition = "attachment" if attachment else "inline"
    parameters = {"ResponseContentDisposition": f'{disposition}; filename="{filename}"'}
    if content_type:
        parameters["ResponseContentType"] = content_type
    return HttpResponseRedirect(default_storage.url(name, parameters=parameters))


# An evaluation's files, as its page lists them and the API serves them.
EVALUATION_FILES = {
    EVALUATION_VIDEO: "Video (WebM)",
    EVALUATION_TRACE: "Simulation trace (CSV)",
    EVALUATION_METRICS: "Evaluation metrics (JSON)",
}


def evaluation_download(request: HttpRequest, evaluation: EvaluationJob, name: str) -> HttpResponse:
    """The evaluation's file ``name`` (one of ``EVALUATION_FILES``) for a racer whose right to it
    the caller has checked: the video to play where it is opened, the others as attachments;
    ``FileNotFoundError`` for a name that is not one, or a file not written (yet)."""
    stored = path(evaluation.model, evaluation_prefix(evaluation) + name)
    if name not in EVALUATION_FILES or not default_storage.exists(stored):
        raise FileNotFoundError(name)
    video = name == EVALUATION_VIDEO
    filename = f"{evaluation.model.name}-evaluation-{evaluation.pk}-{name.replace('/', '-')}"
    content_type = "video/webm" if video else None
    return download(request, stored, filename, attachment=not video, content_type=content_type)


def delete_all(model: RLModel) -> int:
    """Delete every stored object under the model's prefix; how many there were. Never inside a
    transaction (a bucket's listing and deletes are requests)."""
    outside_transaction("Files deleted from storage")
    return _delete_tree(path(model, "").rstrip("/"))


def _delete_tree(directory: str) -> int:
    try:
        folders, files = default_storage.listdir(directory)
    except FileNotFoundError:
        return 0
    for file in files:
        default_storage.delete(f"{directory}/{file}")
    removed = len(files) + sum(_delete_tree(f"{directory}/{folder}") for folder in folders)
    if isinstance(default_storage, FileSystemStorage):
        default_storage.delete(directory)  # the emptied folder
    return removed


def model_files(model: RLModel) -> dict[str, str]:
    """DeepRacer's description of a model: its metadata, reward function and settings (the
    hyperparameters.json as DeepRacer writes it: every key, DeepRacer's spellings)."""
    return {
        "model_metadata.json": json.dumps(model.metadata(), indent=2),
        "reward_function.py": model.reward_function,
        "hyperparameters.json": deepracer_json(model.algorithm, model.hyperparameters),
        "training_params.yaml": yaml.safe_dump(training_params(model), sort_keys=True),
    }


def write_model_files(model: RLModel) -> None:
    for relative, text in model_files(model).items():
        save(model, relative, text)


def training_params(model: RLModel) -> dict:
    """The environment side of the configuration, as DeepRacer's training_params.yaml names it."""
    if model.world_name:  # its own route file, reversed as simapp reverses it
        world_name = model.world_name
        held = sim_tracks.load(model.track.name).on_route(world_name)
        reverse = held.direction != model.direction
    else:
        world_name, reverse = sim_tracks.deepracer_world(model.track.name, model.direction)
    params = {"WORLD_NAME": world_name, "REVERSE_DIR": reverse}
    suffix = {"clockwise": "_cw", "counterclockwise": "_ccw"}[model.direction]
    if not reverse and world_name.endswith(suffix) and not model.world_name:
        # The direction's own route file, named as DeepRacer on AWS names it: the bare track and
        # TRACK_DIRECTION_CLOCKWISE (SimulationEnvironmentHelper.ts:53-56, 61af778), from which
        # simapp adds the suffix back (yaml_file.py:228-246, 01f5f01).
        params["WORLD_NAME"] = world_name.removesuffix(suffix)
        params["TRACK_DIRECTION_CLOCKWISE"] = model.direction == "clockwise"
    params |= {
        "RACE_TYPE": model.race_type,
        "ALTERNATE_DRIVING_DIRECTION": False,
        "CHANGE_START_POSITION": True,
        "NUMBER_OF_RESETS": 0,
        "JOB_TYPE": "TRAINING",
        "MAX_TRAINING_TIME_MINUTES": model.max_minutes,
        "NUM_WORKERS": model.workers,
        "MULTI_TRACK": [model.track.name, *model.extra_tracks],
        "CAR_NAME": model.name,
        # DeepRacer for Cloud's scripts/training/prepare-config.py:54 and :58; simapp's values
        # (bundle/markov/metrics/constants.py:163-167, 01f5f01) are our BestCheckpointBy's.
        "ENABLE_DOMAIN_RANDOMIZATION": model.domain_randomisation,
        "BEST_MODEL_METRIC": str(model.best_checkpoint_by),  # an enum until read back
        "MIN_EVAL_TRIALS": model.evaluation_trials,  # prepare-config.py:55 (2eb1a1f)
    }
    if model.boxes:
        params["NUMBER_OF_OBSTACLES"] = model.boxes.get("count", 3)
        params["RANDOMIZE_OBSTACLE_LOCATIONS"] = bool(model.boxes.get("randomize"))
    if model.bots:
        params["NUMBER_OF_BOT_CARS"] = model.bots.get("count", 3)
        params["BOT_CAR_SPEED"] = model.bots.get("speed", 0.5)
        params["IS_LANE_CHANGE"] = bool(model.bots.get("lane_changes"))
    return params
