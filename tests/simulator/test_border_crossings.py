"""The route check's crossing search: it compares only segments near each other (a grid), so
the largest route file an upload allows is checked quickly, and finds what comparing every
segment with every other finds."""

import numpy as np
import pytest

from simulator import tracks
from tests import routes


def every_pair_crossing(first, second):
    """The first proper crossing by comparing every segment with every other (the definition)."""
    a, b = first[:-1], first[1:]
    c, d = (a, b) if second is None else (second[:-1], second[1:])
    turn = tracks._orientation
    for i in range(len(a)):
        for j in range(i + 1 if second is None else 0, len(c)):
            if turn(a[i], b[i], c[j]) * turn(a[i], b[i], d[j]) < 0 and (
                turn(c[j], d[j], a[i]) * turn(c[j], d[j], b[i]) < 0
            ):
                return i, j
    return None


def test_it_finds_the_first_crossing_that_comparing_every_pair_finds():
    rng = np.random.default_rng(42)
    for trial in range(200):
        points = rng.normal(size=(int(rng.integers(3, 30)), 2))
        if trial % 3 == 0:  # points on a lattice: segments that touch, overlap, or share ends
            points = np.round(points * 2) / 2
        other = None if trial % 2 else points + rng.normal(scale=0.3, size=points.shape)
        assert tracks._first_crossing(points, other) == every_pair_crossing(points, other)


def test_it_finds_a_kink_deep_in_a_route_of_the_largest_size_an_upload_allows():
    # 8 MiB of float64 rows of six: about 174,000 waypoints, as the upload that held the lock.
    route = routes.counterclockwise(points=174_000, radii=(900.0, 600.0))
    route[[150_000, 150_001], 2:4] = route[[150_001, 150_000], 2:4]
    with pytest.raises(tracks.TrackError, match="between waypoints 149999 and 150001"):
        tracks.validate_array(route)
    route[[150_000, 150_001], 2:4] = route[[150_001, 150_000], 2:4]
    tracks.validate_array(route)


def test_waypoints_crowded_past_what_can_be_checked_are_refused_in_words(monkeypatch):
    monkeypatch.setattr(tracks, "GRID_PAIRS", 1_000)
    route = routes.counterclockwise(points=2_000)
    with pytest.raises(tracks.TrackError, match="crowd too closely"):
        tracks.validate_array(route)
