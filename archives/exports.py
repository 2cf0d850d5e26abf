"""What a racer downloads (docs/models.md, "Downloads"): the archives for the physical car,
for other runtimes (ONNX) and of the virtual model, each kept in storage under the model's prefix
(``exports/``) once built.

The physical car gets ``physicalmodel-<name>.tar.gz`` as DeepRacer builds it:
``model_metadata.json`` at the root and the policy as a TensorFlow frozen graph at
``agent/model.pb`` (deepracer-simapp
bundle/markov/boto/s3/files/checkpoint_files/tensorflow_model.py:355-371 and
deepracer-for-cloud scripts/upload/upload-car.sh:53-57). The car's model loader takes the one
``.pb`` in the archive and ``model_metadata.json`` from its root (aws-deepracer-systems-pkg
model_loader_node.py:408-438, model_install_state.py:99-121); its model optimizer converts the
graph with OpenVINO, feeding DeepRacer's input nodes and reading its output node (``car_graph``).

``onnxmodel-<name>.tar.gz`` holds the same policy as ONNX (``model.onnx``, with
``model_metadata.json``) for custom cars and other runtimes: inputs named after the sensors,
grayscale bytes (0-255, as float32) of shape (1, 1, 120, 160), or (1, 2, 120, 160) for stereo,
plus the lidar (``LIDAR``: 64 distances in metres; ``SECTOR_LIDAR``: 8 bits) when the car has one.
It gives ``probabilities``, one per action of ``model_metadata.json`` (discrete), or ``action``,
steering and speed each in [-1, 1] of its range (continuous), as the car's navigation scales it.

The virtual model, ``virtualmodel-<name>.tar.gz``, holds what another Pitlane (or a DeepRacer
toolchain) needs to go on training: ``model_metadata.json``, ``reward_function.py``,
``training_params.yaml``, ``hyperparameters.json`` (DeepRacer's names and spellings, also at
``ip/hyperparameters.json`` where DeepRacer keeps it), the best and the last
checkpoints, the metrics, and ``pitlane.json`` (the settings
DeepRacer's files do not carry: track, direction, race type, network seed and layout, workers;
and the time the model trained, which its page shows). Beside DeepRacer's files, left as they
are: ``pitlane-history.json``, each iteration's figures exactly as the model's page shows them
(DeepRacer's metrics round them) and which iterations the best and last checkpoints hold; and the
simulation traces where DeepRacer keeps them (``training-simtrace/<n>-iteration.csv``,
``evaluation-<time>/evaluation-simtrace/0-iteration.csv``), up to ``TRACES_LIMIT``. Unpacked, it is
a folder DeepRacer on AWS imports: the best and the last checkpoints are simapp's ``model/``
folder (``simapp_model_folder``: TensorFlow checkpoints, which the import here reads back to the
bit), and the metrics are also where DeepRacer on AWS looks for them (``DOA_METRICS``). Only a
model of Pitlane's first networks, which DeepRacer's names do not fit, keeps its checkpoints as
safetensors under ``checkpoints/``.
"""

from __future__ import annotations

import hashlib
import io
import json
import tarfile
import tempfile
import time
from dataclasses import dataclass

from django.core.files.storage import default_storage
from django.db.models import Sum

from archives import history, logs_archive
from common.refusals import Refused
from common.transactions import outside_transaction
from rl import hyperparameters
from training import artifacts, configuration, selectors
from training.models import RLModel

CAR_GRAPH = "agent/model.pb"  # where simapp puts it (tensorflow_model.py:355-371, 01f5f01)
PITLANE_SETTINGS = "pitlane.json"
HYPERPARAMETERS = "ip/hyperparameters.json"  # simapp bundle/markov/boto/s3/constants.py:43
MODEL_FOLDER = "model/"  # simapp's checkpoints and pointers (constants.py:50, 294-300)
# Where DeepRacer on AWS's import finds a model's training metrics: the first object under
# metrics/training/ whose key holds "training-" (deepracer-on-aws 61af778 ImportHelper.ts:84-91).
DOA_METRICS = "metrics/training/training-{name}.json"
# What a virtual archive holds beyond its hashed members (a new layout is a new export): 2 added
# simapp's model/ folder and DeepRacer on AWS's metrics.
VIRTUAL_LAYOUT = 2
# The best and last checkpoints, ours, where a virtual archive of Pitlane's first networks keeps
# them (a DeepRacer network's are in MODEL_FOLDER instead).
EXPORTED = artifacts.EXPORTED_CHECKPOINTS
FORMAT = 2  # of pitlane.json; 2 added network_layout
MiB = 1024 * 1024
# [bytes] of simulation traces a virtual model's archive carries, and an import keeps: a long
# training's traces run to gigabytes; the newest iterations' come first.
TRACES_LIMIT = 64 * MiB
MAX_TRACES = 1000  # files: an import reads at most imports.MAX_MEMBERS


class ExportRefused(Refused):
    """The model has nothing to export yet; the message says why."""


@dataclass(frozen=True)
class Export:
    """An archive in storage: its storage name and the name the racer's browser saves it as."""

    name: str
    filename: str


def physical(model: RLModel, which: str = "best") -> Export:
    """The physical-car archive of the model's ``which`` checkpoint, built once per checkpoint."""
    if model.network_layout != hyperparameters.NETWORK_LAYOUT:
        raise ExportRefused(
            "This model was trained before Pitlane's networks were DeepRacer's, so the car cannot "
            "run it (nor a clone of it, which keeps its network): train a new model with the same "
            "settings for the car, or download this one as ONNX."
        )
    weights = _checkpoint(model, which)
    export = Export(
        artifacts.path(model, f"exports/physical-{_digest(weights)}.tar.gz"),
        f"physicalmodel-{model.name}.tar.gz",
    )
    if not default_storage.exists(export.name):
        from rl.cargraph import car_graph  # torch: loaded by a process's first export

        graph = car_graph(_policy(model, weights), model.action_space_type == "discrete")
        _store(export.name, {"model_metadata.json": _json(model.metadata()), CAR_GRAPH: graph})
    return export


def onnx(model: RLModel, which: str = "best") -> Export:
    """The ONNX archive of the model's ``which`` checkpoint, built once per checkpoint."""
    weights = _checkpoint(model, which)
    export = Export(
        artifacts.path(model, f"exports/onnx-{_digest(weights)}.tar.gz"),
        f"onnxmodel-{model.name}.tar.gz",
    )
    if not default_storage.exists(export.name):
        from rl.onnxgraph import onnx_graph  # torch: loaded by a process's first export

        graph = onnx_graph(_policy(model, weights), model.action_space_type == "discrete")
        _store(export.name, {"model_metadata.json": _json(model.metadata()), "model.onnx": graph})
    return export


def virtual(model: RLModel) -> Export:
    """The virtual-model archive: everything needed to go on training elsewhere; built once per
    content (its checkpoints, metrics and settings files: a file this console writes
    differently, as when it learnt DeepRacer's spellings, is a new export). Its traces are named
    by their names and sizes (a trace is written once), and read only to build it."""
    stored_metrics = artifacts.path(model, artifacts.TRAINING_METRICS)
    metrics = artifacts.read(stored_metrics) if default_storage.exists(stored_metrics) else None
    members = {name: text.encode() for name, text in artifacts.model_files(model).items()}
    # DeepRacer's hyperparameters.json, where a DeepRacer model has it (ip/) and where Pitlane's
    # exports have always had it (the root).
    members["hyperparameters.json"] = members[HYPERPARAMETERS] = deepracer_hyperparameters(model)
    members.update(
        {
            PITLANE_SETTINGS: _json(pitlane_settings(model)),
            **{name: _checkpoint(model, kept) for kept, name in EXPORTED.items()},
        }
    )
    if metrics is not None:
        members[artifacts.TRAINING_METRICS] = metrics
    members.update(_exact_history(model))
    traces = chosen_traces(model)
    content = hashlib.sha256(f"layout {VIRTUAL_LAYOUT}".encode())
    for name, data in sorted(members.items()):
        content.update(name.encode() + b"\0" + hashlib.sha256(data).digest())
    for trace in sorted(traces):
        content.update(f"{trace.relative}\0{trace.size}\0".encode())
    export = Export(
        artifacts.path(model, f"exports/virtual-{content.hexdigest()[:16]}.tar.gz"),
        f"virtualmodel-{model.name}.tar.gz",
    )
    if not default_storage.exists(export.name):
        if model.network_layout == hyperparameters.NETWORK_LAYOUT:
            # DeepRacer's networks: their weights once, as simapp keeps them
            weights = {kept: members.pop(name) for kept, name in EXPORTED.items()}
            members.update(simapp_model_folder(model, weights))
        if metrics is not None:
            members[DOA_METRICS.format(name=model.name)] = metrics
        members.update({trace.relative: artifacts.read(trace.stored) for trace in traces})
        _store(export.name, members)
    return export


def simapp_model_folder(model: RLModel, weights: dict[str, bytes]) -> dict[str, bytes]:
    """The ``model/`` folder as simapp's training leaves it and DeepRacer on AWS's import
    validates it (simapp validation_worker.py:60-105, 141-144): ``model_metadata.json``; the best
    and the last checkpoints (``weights``, ours, by ``EXPORTED``'s keys) as TensorFlow's,
    ``<N>_Step-<steps>.ckpt``, under rl_coach's names (``rl.tfweights.tensors``: every weight of a
    PPO model; a SAC model's target Q networks start again as copies of its Q networks, as
    rl_coach restores them, savers.py:36-38), which ``deepracer_checkpoints.json``
    names (deepracer_checkpoint_json.py:83-131; ``avg_eval_metric`` null where not measured,
    s3_metrics.py:259-263) and ``.coach_checkpoint`` points to, the last (rl_coach_checkpoint.py:
    159-179). Not simapp's frozen graphs (``model_<N>.pb``, tensorflow_model.py:290-327): neither
    DeepRacer on AWS's import nor the validator reads them, and the car's is the physical
    download; they would add half the checkpoints' size again."""
    from rl import tfcheckpoint, tfweights  # torch: loaded by a process's first export

    folder = {f"{MODEL_FOLDER}model_metadata.json": _json(model.metadata())}
    pointers: dict[str, dict] = {}
    names = {
        which: selectors.model_checkpoint(model=model, which=which) for which in ("best", "last")
    }
    job = model.latest_job
    measured = _BEST_MEASURE.get(str(model.best_checkpoint_by), "")
    for which in EXPORTED:
        stored = names[which]
        number = artifacts.checkpoint_iteration(stored)
        if number is None:  # weights an import or a clone brought: numbered in their order
            number = 2 if which == "last" and names["best"] != stored else 1
        rows = job.iteration_rows.filter(number__lte=number) if job else None
        steps = (rows.aggregate(steps=Sum("steps"))["steps"] or 0) if rows is not None else 0
        row = rows.filter(number=number).first() if rows is not None else None
        checkpoint = f"{number}_Step-{steps}.ckpt"
        index = f"{MODEL_FOLDER}{checkpoint}{tfcheckpoint.SUFFIX_INDEX}"
        if index not in folder:  # best and last may be one checkpoint: written once
            policy = _policy(model, weights[which])
            folder[index], folder[f"{MODEL_FOLDER}{checkpoint}{tfcheckpoint.SUFFIX_DATA}"] = (
                tfcheckpoint.write(tfweights.tensors(policy))
            )
        pointers[f"{which}_checkpoint"] = {
            "name": checkpoint,
            "time_stamp": default_storage.get_modified_time(stored).timestamp(),
            "avg_eval_metric": getattr(row, measured, None) if row else None,
        }
    folder[f"{MODEL_FOLDER}deepracer_checkpoints.json"] = _json(pointers)
    folder[f"{MODEL_FOLDER}.coach_checkpoint"] = pointers["last_checkpoint"]["name"].encode()
    return folder


# The iteration's figure simapp names a best checkpoint by (s3_metrics.py:410-436), by the
# model's BEST_MODEL_METRIC.
_BEST_MEASURE = {
    "progress": "evaluation_completion",
    "reward": "evaluation_reward",
    "laptime": "evaluation_lap_ms",
}


def _exact_history(model: RLModel) -> dict[str, bytes]:
    """Pitlane's exact record of the model's training (``history.EXACT``: each iteration's
    figures, which iterations the checkpoints hold), when it has iterations."""
    job = model.latest_job
    if job is None or not job.iteration_rows.exists():
        return {}
    checkpoints = {
        which: artifacts.checkpoint_iteration(name)
        for which in artifacts.EXPORTED_CHECKPOINTS
        if (name := selectors.model_checkpoint(model=model, which=which))
    }
    return {history.EXACT: _json(history.exact_document(job=job, checkpoints=checkpoints))}


@dataclass(frozen=True, order=True)
class Trace:
    """A simulation trace a virtual archive carries: its name there, in storage, and its size."""

    relative: str
    stored: str
    size: int  # [bytes]


def chosen_traces(model: RLModel) -> list[Trace]:
    """The simulation traces the virtual archive carries, as DeepRacer lays them out
    (``logs_archive``), up to ``TRACES_LIMIT`` and ``MAX_TRACES``: the training's, newest
    iteration first (those an import keeps), then the evaluations', newest first, in the room
    left. Read from storage by name and size only."""
    training, evaluations = logs_archive.trace_files(model)
    room, chosen = TRACES_LIMIT, []
    for relative, stored in [*reversed(training), *reversed(evaluations)]:
        if len(chosen) == MAX_TRACES:
            break
        size = default_storage.size(stored)
        if size <= room:
            room -= size
            chosen.append(Trace(relative, stored, size))
    return chosen


def deepracer_hyperparameters(model: RLModel) -> bytes:
    """The model's hyperparameters.json as DeepRacer writes it: every key of the algorithm, the
    ones this console keeps without using included, in DeepRacer's spellings, sorted and
    indented as simapp bundle/markov/sagemaker_graph_manager.py:233 (01f5f01) dumps them."""
    return hyperparameters.deepracer_json(model.algorithm, model.hyperparameters).encode()


def pitlane_settings(model: RLModel) -> dict:
    """What ``model_metadata.json`` and the others leave out, for an import that trains on."""
    return {
        "format": FORMAT,
        **configuration.archived_of(model),
        "training_seconds": round(model.jobs.aggregate(s=Sum("training_seconds"))["s"] or 0, 1),
    }


def _policy(model: RLModel, weights: bytes):
    """The model's policy with ``weights`` (a checkpoint)."""
    from rl.policies import Policy  # torch: loaded by a process's first export

    policy = Policy.for_environment(
        model.algorithm, model.architecture, model.environment_settings(), loading=True
    )
    policy.load_checkpoint(weights)
    return policy


def _checkpoint(model: RLModel, which: str) -> bytes:
    name = selectors.model_checkpoint(model=model, which=which)
    if name is None:
        raise ExportRefused("This model has no trained weights yet: train it first.")
    if not selectors.checkpoint_trained(model=model, name=name):
        raise ExportRefused(selectors.untrained_refusal(model=model, doing="download"))
    return artifacts.read(name)


def _digest(data: bytes) -> str:
    """What names an export: the weights it holds (so a changed checkpoint is a new export)."""
    return hashlib.sha256(data).hexdigest()[:16]


def _json(document: dict) -> bytes:
    return json.dumps(document, indent=2).encode()


def _store(name: str, members: dict[str, bytes]) -> None:
    """A gzipped tar of ``members`` (relative name: bytes) saved in storage at ``name``."""
    outside_transaction("An export written to storage")
    with tempfile.SpooledTemporaryFile(max_size=16 * 1024 * 1024) as spool:
        with tarfile.open(fileobj=spool, mode="w:gz") as archive:
            for relative, data in members.items():
                info = tarfile.TarInfo(relative)
                info.size, info.mtime, info.mode = len(data), int(time.time()), 0o644
                archive.addfile(info, io.BytesIO(data))
        spool.seek(0)
        if default_storage.exists(name):
            default_storage.delete(name)
        default_storage.save(name, spool)
