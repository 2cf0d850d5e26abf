"""A model's logs as one archive laid out as a DeepRacer model folder, the way
DeepRacer-for-Cloud keeps one in its bucket, so that the community's log-analysis notebooks and
deepracer-utils (``DeepRacerLog(folder)``) open it unchanged once it is extracted:

    <model>/model/model_metadata.json
    <model>/ip/hyperparameters.json
    <model>/reward_function.py
    <model>/training_params.yaml
    <model>/training-simtrace/<n>-iteration.csv             iteration n + 1, from 0
    <model>/metrics/TrainingMetrics.json
    <model>/evaluation-<YYYYmmddHHMMSS>/evaluation-simtrace/0-iteration.csv
    <model>/metrics/EvaluationMetrics-<YYYYmmddHHMMSS>.json    one pair per evaluation
    <model>/logs/training-log.txt                            the training log, as text

The names are DeepRacer's (simapp bundle/markov/boto/s3/constants.py:43, 50 and
bundle/markov/boto/s3/files/simtrace_video.py:50-54 (01f5f01)) and DeepRacer-for-Cloud's
(its scripts/training/prepare-config.py:24-37 and scripts/evaluation/prepare-config.py:45-55):
the evaluation's timestamp is when it started, in UTC.
"""

from __future__ import annotations

import io
import re
import tarfile
import tempfile
import time
from typing import BinaryIO

from django.core.files.storage import default_storage
from django.http import HttpRequest, HttpResponse

from common.downloads import file_response
from common.refusals import Refused
from training import artifacts, selectors
from training.models import EvaluationJob, RLModel

TRAINING_METRICS = "metrics/TrainingMetrics.json"
TRAINING_LOG = "logs/training-log.txt"
NO_LOGS = (
    "This model has no logs yet: they appear after its first training iteration or its first "
    "evaluation."
)
TIMESTAMP = "%Y%m%d%H%M%S"  # 14 digits: what deepracer-utils looks for in evaluation-<...>


class LogsRefused(Refused):
    """There are no logs to download yet; the message says so, for the racer."""


def filename(model: RLModel) -> str:
    return f"logs-{_folder(model)}.tar.gz"


def has_logs(model: RLModel) -> bool:
    """Whether the model has a training iteration's files or a finished evaluation to archive."""
    return bool(_stored_files(model))


def download(request: HttpRequest, model: RLModel) -> HttpResponse:
    """The archive as a download, built for this request (its traces grow while the model
    trains, so another request's bytes differ: no ranges); ``LogsRefused`` where there is
    nothing to put in it."""
    archive = tempfile.TemporaryFile()  # noqa: SIM115 (the response closes it once sent)
    try:
        write(model, archive)
    except BaseException:
        archive.close()
        raise
    return file_response(
        request,
        archive,
        filename=filename(model),
        attachment=True,
        content_type="application/gzip",
        ranges=False,
    )


def write(model: RLModel, target: BinaryIO) -> None:
    """Write the model's logs archive (gzipped tar) to ``target``; ``LogsRefused`` when the model
    has neither a training iteration's files nor a finished evaluation yet."""
    stored = _stored_files(model)
    if not stored:
        raise LogsRefused(NO_LOGS)
    root = _folder(model)
    with tarfile.open(fileobj=target, mode="w:gz") as archive:
        for relative, text in artifacts.model_files(model).items():
            name = "model/model_metadata.json" if relative == "model_metadata.json" else relative
            if relative == "hyperparameters.json":
                name = "ip/hyperparameters.json"
            _add_bytes(archive, f"{root}/{name}", text.encode())
        for relative, name in stored:
            _add_stored(archive, f"{root}/{relative}", name)
        log = "".join(selectors.model_log_lines(model=model)).encode()
        _add_bytes(archive, f"{root}/{TRAINING_LOG}", log)


def _stored_files(model: RLModel) -> list[tuple[str, str]]:
    """(name in the archive, storage name) of the model's traces and metrics."""
    files = _training_traces(model)
    prefix = artifacts.path(model, "")
    if files and default_storage.exists(prefix + artifacts.TRAINING_METRICS):
        files.append((TRAINING_METRICS, prefix + artifacts.TRAINING_METRICS))
    for trace, metrics in _evaluation_files(model):
        files.append(trace)
        if metrics is not None:
            files.append(metrics)
    return files


def trace_files(model: RLModel) -> tuple[list[tuple[str, str]], list[tuple[str, str]]]:
    """(name in a DeepRacer model folder, storage name) of the model's simulation traces: each
    training iteration's, in order; and each finished evaluation's, in order."""
    return _training_traces(model), [trace for trace, _ in _evaluation_files(model)]


def _training_traces(model: RLModel) -> list[tuple[str, str]]:
    prefix = artifacts.path(model, "")
    try:
        _, names = default_storage.listdir(prefix + "training-simtrace")
    except FileNotFoundError:
        names = []
    found = sorted(
        (int(match[1]), name)
        for name in names
        if (match := re.fullmatch(r"(\d+)-iteration\.csv", name))
    )
    return [(f"training-simtrace/{name}", f"{prefix}training-simtrace/{name}") for _, name in found]


def _evaluation_files(model: RLModel):
    """(trace, metrics or None) of each finished evaluation with a trace, each as (name in the
    archive, storage name)."""
    stamps: set[str] = set()
    evaluations = model.evaluations.filter(status=EvaluationJob.Status.COMPLETED).order_by("pk")
    for evaluation in evaluations:
        trace = artifacts.path(
            model, artifacts.evaluation_prefix(evaluation) + artifacts.EVALUATION_TRACE
        )
        if not default_storage.exists(trace):
            continue
        stamp = _stamp(evaluation, stamps)
        metrics = artifacts.path(
            model, artifacts.evaluation_prefix(evaluation) + artifacts.EVALUATION_METRICS
        )
        yield (
            (f"evaluation-{stamp}/evaluation-simtrace/0-iteration.csv", trace),
            (f"metrics/EvaluationMetrics-{stamp}.json", metrics)
            if default_storage.exists(metrics)
            else None,
        )


def _stamp(evaluation: EvaluationJob, taken: set[str]) -> str:
    """The evaluation's start in UTC to the second; a second later when another evaluation
    started in the same second, so that every evaluation has its own folder."""
    seconds = (evaluation.started_at or evaluation.created_at).timestamp()
    while (stamp := time.strftime(TIMESTAMP, time.gmtime(seconds))) in taken:
        seconds += 1
    taken.add(stamp)
    return stamp


def _folder(model: RLModel) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", model.name).strip("-.") or f"model-{model.pk}"


def _add_bytes(archive: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode = len(data), int(time.time()), 0o644
    archive.addfile(info, io.BytesIO(data))


def _add_stored(archive: tarfile.TarFile, name: str, stored: str) -> None:
    info = tarfile.TarInfo(name)
    info.size, info.mtime, info.mode = default_storage.size(stored), int(time.time()), 0o644
    with default_storage.open(stored, "rb") as source:
        archive.addfile(info, source)
