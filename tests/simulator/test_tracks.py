import numpy as np
import pytest

from simulator import tracks
from simulator.tracks import TrackError
from simulator.tracks.generate import SPECS, build


def test_the_built_in_tracks_are_listed_and_load():
    assert tracks.names() == ["pitlane-oval", "kidney-bean", "clover-loop"]
    for name in tracks.names():
        track = tracks.load(name)
        assert track.centre.shape == track.inner.shape == track.outer.shape
        assert track.centre.shape[1] == 2
        np.testing.assert_allclose(track.centre[0], track.centre[-1])  # a closed loop
        assert track.width == pytest.approx(1.066, abs=1e-3)


def test_a_built_in_track_has_the_length_its_spec_asks_for():
    for spec in SPECS:
        assert tracks.load(spec.name).length == pytest.approx(spec.length, rel=1e-6)


def test_the_committed_track_files_are_what_the_generator_makes():
    for spec in SPECS:
        committed = np.load(tracks.DATA_DIR / f"{spec.name}.npy")
        np.testing.assert_allclose(committed, build(spec))


def test_a_deepracer_npy_file_loads_by_path(tmp_path):
    path = tmp_path / "my_track.npy"
    np.save(path, np.load(tracks.DATA_DIR / "pitlane-oval.npy"))
    track = tracks.load(path)
    assert track.name == "my_track"
    assert track.length == pytest.approx(16.5)


def test_an_open_track_file_is_closed_on_load(tmp_path):
    path = tmp_path / "open.npy"
    np.save(path, np.load(tracks.DATA_DIR / "pitlane-oval.npy")[:-1])
    track = tracks.load(path)
    np.testing.assert_allclose(track.centre[0], track.centre[-1])
    assert track.length == pytest.approx(16.5)


@pytest.mark.parametrize(
    ("array", "message"),
    [
        (np.zeros((50, 4)), r"\(N, 6\) array.*shape \(50, 4\)"),
        (np.zeros((5, 6)), "at least 10 points"),
        (np.full((20, 6), np.nan), "NaN or infinite"),
    ],
)
def test_a_malformed_track_file_is_rejected_with_a_clear_message(tmp_path, array, message):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    with pytest.raises(TrackError, match=message):
        tracks.load(path)


def test_a_track_whose_border_crosses_itself_is_rejected(tmp_path):
    theta = np.linspace(0, 2 * np.pi, 40)
    figure_eight = np.column_stack([np.sin(theta), np.sin(theta) * np.cos(theta)])
    array = np.hstack([figure_eight, figure_eight * 0.9, figure_eight * 1.1])
    path = tmp_path / "eight.npy"
    np.save(path, array)
    with pytest.raises(TrackError, match="inner border of this track crosses itself"):
        tracks.load(path)


def test_a_file_that_is_not_numpy_is_rejected(tmp_path):
    path = tmp_path / "notes.npy"
    path.write_text("not a track")
    with pytest.raises(TrackError, match=r"notes\.npy is not a NumPy \.npy track file"):
        tracks.load(path)


def test_an_unknown_track_name_lists_the_built_in_ones():
    with pytest.raises(TrackError, match=r"No track named 'monza'\. Built-in tracks: pitlane-oval"):
        tracks.load("monza")
