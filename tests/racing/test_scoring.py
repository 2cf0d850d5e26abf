"""Scores from laps: the league's rule, the community methods, and their edge cases."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from racing import scoring
from racing.scoring import BEST_CONSECUTIVE, BEST_LAP, FIRST_CONSECUTIVE, TOTAL_TIME, Lap


def laps(*times: int | None) -> list[Lap]:
    """Lap times in ms; None for a lap that does not count."""
    return [Lap(t or 99_000, t is not None) for t in times]


def test_fewer_than_n_laps_does_not_qualify():
    assert scoring.score(laps(10_000, 11_000), method=FIRST_CONSECUTIVE, size=3) is None


def test_complete_laps_that_are_not_consecutive_do_not_qualify():
    run = laps(10_000, 10_000, None, 10_000, 10_000)
    for method in scoring.METHODS:
        assert scoring.score(run, method=method, size=3) is None


def test_the_leagues_rule_takes_the_first_run_not_a_later_faster_one():
    run = laps(12_000, 12_000, 12_000, None, 9_000, 9_000, 9_000)
    assert scoring.score(run, method=FIRST_CONSECUTIVE, size=3) == 12_000
    assert scoring.score(run, method=BEST_CONSECUTIVE, size=3) == 9_000


def test_the_best_average_takes_the_best_overlapping_window():
    run = laps(13_000, 10_000, 10_000, 10_000, 16_000)
    assert scoring.score(run, method=FIRST_CONSECUTIVE, size=3) == 11_000
    assert scoring.score(run, method=BEST_CONSECUTIVE, size=3) == 10_000


def test_penalties_are_inside_the_lap_times_and_are_not_added_again():
    # 2 s of off-track penalty is already part of the 12,000 ms lap
    assert scoring.score(laps(10_000, 12_000, 11_000), method=FIRST_CONSECUTIVE, size=3) == 11_000


def test_best_lap_and_total_time_need_the_run_too():
    run = laps(None, 10_500, 10_000, 11_000, 9_000)
    assert scoring.score(run, method=BEST_LAP, size=3) == 9_000
    # total time: from the start until the first run ends, the lap that did not count included
    assert scoring.score(run, method=TOTAL_TIME, size=3) == 99_000 + 10_500 + 10_000 + 11_000
    assert scoring.score(laps(9_000, None), method=BEST_LAP, size=3) is None


def test_averages_round_to_the_millisecond_halves_up():
    assert scoring.score(laps(1, 2), method=FIRST_CONSECUTIVE, size=2) == 2  # 1.5 -> 2
    assert scoring.score(laps(1, 1, 2), method=FIRST_CONSECUTIVE, size=3) == 1  # 1.33 -> 1


def test_it_refuses_an_unknown_method_and_an_empty_run():
    with pytest.raises(ValueError, match="unknown ranking method"):
        scoring.score(laps(1), method="FASTEST_FRIEND", size=1)
    with pytest.raises(ValueError, match="at least one lap"):
        scoring.score(laps(1), method=BEST_LAP, size=0)


def reference_windows(run: list[Lap], size: int) -> list[list[int]]:
    """Every run of ``size`` consecutive counted laps, the obvious way."""
    return [
        [lap.time_ms for lap in run[start : start + size]]
        for start in range(len(run) - size + 1)
        if all(lap.counted for lap in run[start : start + size])
    ]


lap_lists = st.lists(
    st.builds(Lap, st.integers(1, 600_000), st.booleans()), min_size=0, max_size=25
)


@given(run=lap_lists, size=st.integers(1, 6))
def test_window_averages_match_a_simple_reference(run, size):
    windows = reference_windows(run, size)
    first = scoring.score(run, method=FIRST_CONSECUTIVE, size=size)
    best = scoring.score(run, method=BEST_CONSECUTIVE, size=size)
    if not windows:
        assert first is None and best is None
        return
    averages = [sum(window) / size for window in windows]
    assert abs(first - averages[0]) <= 0.5
    assert abs(best - min(averages)) <= 0.5
    assert best <= first
