"""DeepRacer's best checkpoint by the racer's metric (DR_TRAIN_BEST_MODEL_METRIC), over a job's
iterations: ``jobs.checkpoints``."""

import pytest

from jobs.checkpoints import UNFINISHED_LAP_MS, best_iteration, evaluation_means
from training.models import Iteration


def rows() -> list[Iteration]:
    """Four iterations' evaluations: 2 goes furthest, 3 earns the most reward, 4 laps fastest
    on average; 1 was never evaluated."""
    figures = {  # number: (mean progress, mean reward, mean lap time [ms])
        1: (None, None, None),
        2: (100.0, 40.0, 9_500.0),
        3: (80.0, 95.0, (8_000 + UNFINISHED_LAP_MS) / 2),
        4: (100.0, 60.0, 9_000.0),
    }
    return [
        Iteration(
            number=number,
            evaluation_completion=progress,
            evaluation_reward=reward,
            evaluation_lap_ms=lap,
        )
        for number, (progress, reward, lap) in figures.items()
    ]


@pytest.mark.parametrize(("metric", "best"), [("progress", 4), ("reward", 3), ("laptime", 4)])
def test_the_metric_decides_which_iteration_is_best(metric, best):
    assert best_iteration(rows=rows(), metric=metric).number == best


def test_a_tie_goes_to_the_newer_checkpoint_whatever_order_the_rows_come_in():
    tied = rows()
    tied[3].evaluation_completion = tied[1].evaluation_completion = 100.0
    assert best_iteration(rows=reversed(tied), metric="progress").number == 4
    tied[1].evaluation_lap_ms = tied[3].evaluation_lap_ms
    assert best_iteration(rows=reversed(tied), metric="laptime").number == 4


def test_by_lap_time_a_faster_lap_beats_more_progress_and_no_lap_counts_999999_ms():
    slow = {"progress": 100.0, "reward": 10.0, "lap_time": 12.0}
    fast_once = {"progress": 60.0, "reward": 10.0, "lap_time": None}
    means = evaluation_means([slow, fast_once])
    assert means == {
        "evaluation_completion": 80.0,
        "evaluation_reward": 10.0,
        "evaluation_lap_ms": (12_000 + 999_999) / 2,
    }


def test_no_iteration_is_best_before_one_is_evaluated():
    assert best_iteration(rows=rows()[:1], metric="reward") is None
