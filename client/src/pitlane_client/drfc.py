"""A DeepRacer for Cloud model in S3 (``s3://bucket/prefix``), packed as the archive Pitlane's
import reads: what the model's prefix holds of it, and nothing else of the bucket.

The layout is DeepRacer's own, as DeepRacer for Cloud (DRfC, aws-deepracer-community/
deepracer-for-cloud at 2eb1a1f) and its simulation (simapp, aws-deepracer-community/
deepracer-simapp at 01f5f01, under bundle/) write it:

- ``reward_function.py``, copied into the prefix when training starts (DRfC
  scripts/training/prepare-config.py:111-116);
- ``training_params.yaml``, or one ``training_params_<N>.yaml`` per worker where workers train
  on different settings (prepare-config.py:98-99, 130-135, 218-226): the first is read;
- ``model/model_metadata.json`` and ``ip/hyperparameters.json``, written by the training worker
  (simapp markov/training_worker.py:296-301, 357-362; markov/boto/s3/constants.py:43,50), and
  ``model_metadata.json`` at the root where ``dr-upload-model`` copied the model
  (scripts/upload/upload-model.sh:222-227);
- under ``model/``, the checkpoints ``<N>_Step-<steps>.ckpt`` (TensorFlow's ``.index``,
  ``.data-00000-of-00001`` and ``.meta``: simapp multi_agent_coach/multi_agent_graph_manager.py:
  642-643), the last four and the best kept (markov/boto/s3/files/checkpoint_files/
  tensorflow_model.py:408-440); ``deepracer_checkpoints.json`` naming the best and the last
  (``{"best_checkpoint": {"name": ...}, "last_checkpoint": {...}}``, markov/metrics/
  s3_metrics.py:443-449), ``.coach_checkpoint`` the latest (rl_coach checkpoint.py:140-146), and a
  frozen graph ``model_<N>.pb`` per checkpoint (tensorflow_model.py:306-317). The best and the
  last are taken as ``dr-upload-model`` takes them (upload-model.sh:157-192): by the JSON's
  names, else the pointer's, else the highest number;
- ``metrics/TrainingMetrics.json``, the first worker's episodes (DRfC prepare-config.py:24-28;
  the others' ``TrainingMetrics_<N>.json``, simapp markov/rollout_worker.py:586-594);
- ``training-simtrace/<N>-iteration.csv``, the first worker's traces (simapp
  markov/rollout_worker.py:650-683): the newest, up to ``TRACES_BYTES`` together.
"""

from __future__ import annotations

import json
import re
import tarfile
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import IO, Any

__all__ = ["DrfcUnreadable", "Packed", "pack", "parse_url"]

SETTINGS_FILES = (
    "reward_function.py",
    "model_metadata.json",
    "training_params.yaml",
    "model/model_metadata.json",
    "ip/hyperparameters.json",
    "metrics/TrainingMetrics.json",
)
POINTERS = ("model/deepracer_checkpoints.json", "model/.coach_checkpoint")
CHECKPOINT_FILES = (".index", ".data-00000-of-00001")  # the .meta graph is not needed
STEP = re.compile(r"model/(\d+)_Step-\d+\.ckpt\.index")
GRAPH = re.compile(r"model/model_(\d+)\.pb")
RUNS = re.compile(r"training_params_(\d+)\.yaml")
TRACE = re.compile(r"training-simtrace/(\d+)-iteration\.csv")
POINTER_BYTES = 64 * 1024  # [bytes] the most a checkpoint pointer is read to
TRACES_BYTES = 64 * 1024 * 1024  # [bytes] of the newest training traces packed
MAX_BYTES = 256 * 1024 * 1024  # [bytes] the most Pitlane's import takes in one archive


class DrfcUnreadable(ValueError):
    """The prefix holds no model Pitlane can import; the message says why."""


@dataclass
class Packed:
    """What was packed: each file by its path in the archive, with its key in the bucket; the
    notes on what was left behind."""

    files: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    size: int = 0  # [bytes] of the files, together


def parse_url(url: str) -> tuple[str, str]:
    """``s3://bucket/prefix`` as the bucket and the prefix (no slash at either end)."""
    bucket, _, prefix = url.removeprefix("s3://").partition("/")
    if not url.startswith("s3://") or not bucket or not prefix.strip("/"):
        raise DrfcUnreadable(
            f"{url!r} is not a model's place in S3: give s3://<bucket>/<model prefix>, as "
            "DeepRacer for Cloud's DR_LOCAL_S3_BUCKET and DR_LOCAL_S3_MODEL_PREFIX name it."
        )
    return bucket, prefix.strip("/")


def pack(
    s3: Any,
    url: str,
    into: IO[bytes],
    progress: Callable[[int, int], None] | None = None,
) -> Packed:
    """The model at ``url`` written into ``into`` as a tar archive, read with ``s3`` (a boto3
    S3 client, or anything with its ``list_objects_v2`` and ``get_object``);
    ``progress(done, total)`` [bytes] as it is read."""
    bucket, prefix = parse_url(url)
    sizes = _listed(s3, bucket, prefix)
    if not sizes:
        raise DrfcUnreadable(f"Nothing is stored under {url}: is the bucket or prefix misspelt?")
    packed = Packed()
    for path in SETTINGS_FILES:
        if path in sizes:
            packed.files[path] = path
    if "training_params.yaml" not in sizes:
        runs = sorted((int(m[1]), path) for path in sizes if (m := RUNS.fullmatch(path)))
        if runs:
            packed.files["training_params.yaml"] = runs[0][1]
            if len(runs) > 1:
                packed.notes.append(
                    f"{runs[0][1]} gave the track and race: the other workers' "
                    f"({', '.join(path for _, path in runs[1:])}) are left behind."
                )
    if not any(path.endswith("model_metadata.json") for path in packed.files):
        raise DrfcUnreadable(
            f"{url} holds no model/model_metadata.json: is it a DeepRacer for Cloud model's "
            "prefix (DR_LOCAL_S3_MODEL_PREFIX), and has its training begun?"
        )
    pointers = {path: _read(s3, bucket, prefix, path) for path in POINTERS if path in sizes}
    _checkpoints_packed(packed, sizes, pointers)
    _traces_packed(packed, sizes)
    packed.size = sum(sizes[key] for key in packed.files.values())
    if packed.size > MAX_BYTES:
        raise DrfcUnreadable(
            f"The model's files under {url} come to {packed.size / 2**20:,.0f} MiB; Pitlane "
            f"imports at most {MAX_BYTES / 2**20:,.0f} MiB."
        )
    _write(s3, bucket, prefix, packed, sizes, into, progress)
    return packed


def _listed(s3: Any, bucket: str, prefix: str) -> dict[str, int]:
    """[bytes] each object under the prefix, by its path below it."""
    sizes: dict[str, int] = {}
    asked = {"Bucket": bucket, "Prefix": f"{prefix}/"}
    while True:
        page = s3.list_objects_v2(**asked)
        for item in page.get("Contents", []):
            sizes[item["Key"][len(prefix) + 1 :]] = int(item["Size"])
        if not page.get("IsTruncated"):
            return sizes
        asked["ContinuationToken"] = page["NextContinuationToken"]


def _read(s3: Any, bucket: str, prefix: str, path: str) -> bytes:
    body = s3.get_object(Bucket=bucket, Key=f"{prefix}/{path}")["Body"]
    return body.read(POINTER_BYTES)


def _checkpoints_packed(packed: Packed, sizes: dict[str, int], pointers: dict) -> None:
    """The best and the last checkpoint, with their pointers; the frozen graph of the best only
    where no checkpoint is whole (the graph holds the policy alone)."""
    whole = {
        path.removeprefix("model/").removesuffix(".index")
        for path in sizes
        if STEP.fullmatch(path) and f"{path.removesuffix('.index')}{CHECKPOINT_FILES[1]}" in sizes
    }
    named, latest = _pointed(pointers)
    chosen = [name for name in named if name in whole] or [n for n in latest if n in whole]
    if not chosen and whole:
        chosen = [max(whole, key=lambda name: int(name.split("_", 1)[0]))]
    for name in dict.fromkeys(chosen):
        for suffix in CHECKPOINT_FILES:
            packed.files[f"model/{name}{suffix}"] = f"model/{name}{suffix}"
    for path in pointers:
        packed.files[path] = path
    if chosen:
        return
    graphs = sorted((int(m[1]), path) for path in sizes if (m := GRAPH.fullmatch(path)))
    if graphs:
        packed.files[graphs[-1][1]] = graphs[-1][1]


def _pointed(pointers: dict[str, bytes]) -> tuple[list[str], list[str]]:
    """The checkpoints DeepRacer's pointers name: the best and the last, and rl_coach's latest,
    the one to take where those are not there (as ``dr-upload-model`` and Pitlane's import read
    them); a pointer that is not what DeepRacer writes names nothing."""
    try:
        named = json.loads(pointers.get("model/deepracer_checkpoints.json") or b"{}")
    except ValueError:
        named = {}
    entries = (
        [named.get(key) for key in ("best_checkpoint", "last_checkpoint")]
        if isinstance(named, dict)
        else []
    )
    names = [e.get("name") for e in entries if isinstance(e, dict)]
    names = [name for name in names if isinstance(name, str) and name]
    coach = pointers.get("model/.coach_checkpoint", b"").decode("utf-8", "replace").strip()
    return names, [coach] if coach else []


def _traces_packed(packed: Packed, sizes: dict[str, int]) -> None:
    traces = sorted(
        ((int(m[1]), path) for path in sizes if (m := TRACE.fullmatch(path))), reverse=True
    )
    room = TRACES_BYTES
    for _, path in traces:
        if sizes[path] > room:
            break
        room -= sizes[path]
        packed.files[path] = path


def _write(
    s3: Any,
    bucket: str,
    prefix: str,
    packed: Packed,
    sizes: dict[str, int],
    into: IO[bytes],
    progress: Callable[[int, int], None] | None,
) -> None:
    read = _Read(packed.size, progress)
    with tarfile.open(fileobj=into, mode="w") as tar:
        for path, key in packed.files.items():
            info = tarfile.TarInfo(path)
            info.size = sizes[key]
            read.body = s3.get_object(Bucket=bucket, Key=f"{prefix}/{key}")["Body"]
            tar.addfile(info, read)


class _Read:
    """The object being packed (``body``), read through with ``progress(done, total)`` told
    after each read."""

    def __init__(self, total: int, progress: Callable[[int, int], None] | None) -> None:
        self.body: Any = None
        self.total, self.progress, self.done = total, progress, 0

    def read(self, size: int = -1) -> bytes:
        data = self.body.read(size) if size > 0 else self.body.read()
        self.done += len(data)
        if self.progress:
            self.progress(self.done, self.total)
        return data
