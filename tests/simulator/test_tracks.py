import cv2
import numpy as np
import pytest

from simulator import tracks
from simulator.tracks import TrackError
from simulator.tracks.generate import SPECS, build

BUILT_IN = [
    "rookie-loop",
    "pitlane-oval",
    "kidney-bean",
    "s-bend",
    "speedway",
    "clover-loop",
    "hairpin-alley",
    "championship-circuit",
]


def test_the_built_in_tracks_are_listed_in_order_of_difficulty():
    assert tracks.names(origin="pitlane") == BUILT_IN
    difficulties = [tracks.load(name).difficulty for name in BUILT_IN]
    assert set(difficulties) == {"beginner", "intermediate", "advanced", "expert"}


@pytest.mark.parametrize("spec", SPECS, ids=lambda spec: spec.name)
def test_a_built_in_track_is_the_closed_loop_its_spec_describes(spec):
    track = tracks.load(spec.name)
    assert track.centre.shape == track.inner.shape == track.outer.shape
    np.testing.assert_allclose(track.centre[0], track.centre[-1])
    assert track.length == pytest.approx(spec.length, rel=0.005)
    assert track.width == pytest.approx(spec.width, abs=0.002)
    assert track.directions == spec.directions
    preview = cv2.imread(str(tracks.preview_path(spec.name)))
    assert preview.shape[1] == 480


def test_the_beginner_loop_is_sized_like_reinvent_2018():
    track = tracks.load("rookie-loop")
    assert track.length == pytest.approx(17.6, abs=0.05)
    assert track.width == pytest.approx(0.76, abs=0.005)


def test_the_committed_track_files_are_what_the_generator_makes():
    for spec in SPECS:
        np.testing.assert_allclose(np.load(tracks.DATA_DIR / f"{spec.name}.npy"), build(spec))


def test_projection_gives_distance_offset_and_side():
    track = tracks.load("pitlane-oval")
    x, y, _ = track.point_at(1.0, 0.2)  # on the first straight
    distance, offset, left = track.project((float(x), float(y)))
    assert distance == pytest.approx(1.0, abs=0.01)
    assert offset == pytest.approx(0.2, abs=0.01)
    assert left
    assert not track.project(track.point_at(1.0, -0.2)[:2])[2]


def test_contains_width_and_closest_waypoints():
    track = tracks.load("pitlane-oval")
    inside = track.point_at(5.0, 0.5)[:2]
    outside = track.point_at(5.0, 0.6)[:2]
    assert track.contains(inside)
    assert not track.contains(outside)
    assert track.width_at(inside) == pytest.approx(1.066, abs=0.005)
    behind, ahead = track.closest_waypoints(track.point_at(0.2)[:2])
    assert (behind, ahead) == (1, 2)
    last = len(track.centre) - 2
    assert track.closest_waypoints(track.point_at(track.length - 0.01)[:2]) == [last, 0]


def test_driving_clockwise_reverses_the_waypoints_and_the_sides():
    track = tracks.load("kidney-bean")
    reverse = track.with_direction("clockwise")
    np.testing.assert_allclose(reverse.centre, track.centre[::-1])
    point = track.point_at(4.0, 0.3)[:2]
    assert track.project(point)[2] and not reverse.project(point)[2]
    assert reverse.length == pytest.approx(track.length)


def test_a_track_that_allows_one_direction_refuses_the_other():
    with pytest.raises(TrackError, match="cannot be driven clockwise"):
        tracks.load("championship-circuit").with_direction("clockwise")


def test_a_deepracer_npy_file_loads_by_path(tmp_path):
    path = tmp_path / "my_track.npy"
    np.save(path, np.load(tracks.DATA_DIR / "pitlane-oval.npy"))
    track = tracks.load(path)
    assert track.name == "my_track"
    assert track.length == pytest.approx(tracks.load("pitlane-oval").length)


def test_an_open_track_file_is_closed_on_load(tmp_path):
    path = tmp_path / "open.npy"
    np.save(path, np.load(tracks.DATA_DIR / "pitlane-oval.npy")[:-1])
    track = tracks.load(path)
    np.testing.assert_allclose(track.centre[0], track.centre[-1])
    assert track.length == pytest.approx(tracks.load("pitlane-oval").length)


@pytest.mark.parametrize(
    ("array", "message"),
    [
        (np.zeros((50, 4)), r"six numbers: centre x.*This one has shape \(50, 4\)"),
        (np.zeros(12), r"This one has shape \(12,\)"),
        (np.zeros((5, 6)), "at least 3 different waypoints; this route has 1"),
        (
            np.full((20, 6), np.nan),
            r"Waypoint 0 of the route file has NaN or infinity for its centre x",
        ),
        (np.array([["a"] * 6] * 20), "holds numbers; this one holds <U1 values"),
    ],
)
def test_a_malformed_track_file_is_rejected_with_a_clear_message(tmp_path, array, message):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    with pytest.raises(TrackError, match=message):
        tracks.load(path)


def test_a_track_whose_border_crosses_itself_is_rejected(tmp_path):
    theta = np.linspace(0, 2 * np.pi, 40) + 0.05  # no waypoint right at the crossing
    figure_eight = np.column_stack([np.sin(theta), np.sin(theta) * np.cos(theta)])
    path = tmp_path / "eight.npy"
    np.save(path, np.hstack([figure_eight, figure_eight * 0.9, figure_eight * 1.1]))
    with pytest.raises(TrackError, match="inner border of this track crosses itself"):
        tracks.load(path)


def test_a_track_whose_borders_cross_each_other_is_rejected(tmp_path):
    array = np.load(tracks.DATA_DIR / "pitlane-oval.npy").copy()
    array[40:50, 2:4], array[40:50, 4:6] = array[40:50, 4:6].copy(), array[40:50, 2:4].copy()
    path = tmp_path / "twisted.npy"
    np.save(path, array)
    with pytest.raises(TrackError, match="inner and outer borders of this track cross"):
        tracks.load(path)


def test_a_file_that_is_not_numpy_is_rejected(tmp_path):
    path = tmp_path / "notes.npy"
    path.write_text("not a track")
    with pytest.raises(TrackError, match=r"notes\.npy is not a NumPy \.npy track file"):
        tracks.load(path)


def test_an_unknown_track_name_lists_the_built_in_ones():
    with pytest.raises(TrackError, match=r"No track named 'monza'\. Built-in tracks: rookie-loop"):
        tracks.load("monza")
