"""Which checkpoint is a model's best: DeepRacer's rule, by the metric the racer chose.

After each policy update DeepRacer's first worker drives a few evaluation episodes with the new
checkpoint, and the checkpoint whose episodes did best by ``BEST_MODEL_METRIC`` becomes the
best (simapp bundle/markov/metrics/s3_metrics.py:362-375 and 404-442, 01f5f01; DeepRacer for
Cloud sets it from DR_TRAIN_BEST_MODEL_METRIC, scripts/training/prepare-config.py:58):

- ``progress`` (the default): the highest mean progress of the episodes;
- ``reward``: the highest mean of the episodes' total rewards;
- ``laptime``: the lowest mean lap time in milliseconds, an episode that did not finish its lap
  counting 999999 ms.

A tie goes to the newer checkpoint (">=" and "<=" over evaluations that come in order).
"""

from __future__ import annotations

from collections.abc import Iterable
from statistics import mean

from training.models import BestCheckpointBy, Iteration

UNFINISHED_LAP_MS = 999_999  # s3_metrics.py:373
# The Iteration field that holds each metric's mean over the evaluation episodes.
FIELDS = {
    BestCheckpointBy.PROGRESS: "evaluation_completion",
    BestCheckpointBy.REWARD: "evaluation_reward",
    BestCheckpointBy.LAPTIME: "evaluation_lap_ms",
}


def evaluation_means(results: list[dict]) -> dict[str, float]:
    """The means of an iteration's evaluation episodes (each {progress [%], reward, lap_time
    [s] or None}) as ``Iteration`` keeps them, one a metric."""
    return {
        FIELDS[BestCheckpointBy.PROGRESS]: mean(r["progress"] for r in results),
        FIELDS[BestCheckpointBy.REWARD]: mean(r["reward"] for r in results),
        FIELDS[BestCheckpointBy.LAPTIME]: mean(
            round(r["lap_time"] * 1000) if r["lap_time"] is not None else UNFINISHED_LAP_MS
            for r in results
        ),
    }


def best_iteration(*, rows: Iterable[Iteration], metric: str) -> Iteration | None:
    """Of ``rows`` (a job's iterations), the one whose checkpoint is best by ``metric`` (a
    ``BestCheckpointBy``); None when none has that metric measured (none evaluated yet)."""
    field = FIELDS[BestCheckpointBy(metric)]
    lower_is_better = metric == BestCheckpointBy.LAPTIME
    best, best_value = None, None
    for row in sorted(rows, key=lambda row: row.number):
        value = getattr(row, field)
        if value is None:
            continue
        if best_value is None or (value <= best_value if lower_is_better else value >= best_value):
            best, best_value = row, value
    return best
