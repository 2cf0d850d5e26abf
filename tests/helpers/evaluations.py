"""An evaluation's files as it stored them, and its trials' paths read from its trace."""

import csv
import io

from training import artifacts
from training.artifacts import EVALUATION_TRACE as TRACE
from training.models import EvaluationJob


def stored(evaluation: EvaluationJob, name: str) -> bytes:
    """The evaluation's stored file ``name`` (``training.artifacts``' names: its trace, ...)."""
    return artifacts.read(
        artifacts.path(evaluation.model, artifacts.evaluation_prefix(evaluation) + name)
    )


def trial_paths(evaluation: EvaluationJob) -> list[list[tuple[str, str]]]:
    """Each trial's positions, row after row, from its stored trace."""
    rows = csv.DictReader(io.StringIO(stored(evaluation, TRACE).decode()))
    paths: dict[str, list] = {}
    for row in rows:
        paths.setdefault(row["episode"], []).append((row["X"], row["Y"]))
    return list(paths.values())
