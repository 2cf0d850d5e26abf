"""An evaluation's form as a racer sends it, its files as it stored them, and its trials' paths
read from its trace."""

import csv
import io

from training import artifacts
from training.artifacts import EVALUATION_TRACE as TRACE
from training.models import EvaluationJob

# The evaluate page's form as a racer sends it with the defaults: 3 trials on the oval.
EVALUATION_FORM = {
    "track": "pitlane-oval",
    "direction": "counterclockwise",
    "race_type": "TIME_TRIAL",
    "trials": "3",
    "off_track_penalty": "2",
    "crash_penalty": "5",
    "checkpoint": "best",
}


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
