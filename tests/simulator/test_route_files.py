"""DeepRacer route files load as DeepRacer's loader takes them (tests/routes.py makes the files)."""

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from simulator import tracks
from simulator.tracks import TrackError
from tests import routes
from tests.helpers.tracks import claiming

ROOT = Path(__file__).resolve().parents[2]

ACCEPTED = [
    "counterclockwise",
    "clockwise",
    "repeated_point",
    "repeated_border_point",
    "repeated_closing_point",
    "open_loop",
]
REFUSED = {
    "border_crosses_itself": r"^The inner border of this track crosses itself \(between waypoints",
    "borders_cross": r"^The inner and outer borders of this track cross each other",
    "not_a_number": r"^Waypoint 7 of the route file has NaN or infinity for its inner border y;",
    "wrong_shape": r"six numbers: centre x, centre y, .*This one has shape \(61, 4\)\.$",
    "too_few_points": r"at least 3 different waypoints; this route has 2 once repeated points",
    "straight": r"^This route does not come back to where it starts",
}


@pytest.fixture(scope="module")
def route_files(tmp_path_factory):
    directory = tmp_path_factory.mktemp("routes")
    return {path.stem: path for path in routes.write(directory)}


def test_the_route_script_writes_every_kind_of_file_in_deepracers_format(route_files):
    assert set(route_files) == set(ACCEPTED) | set(REFUSED)
    array = np.load(route_files["counterclockwise"])
    assert array.dtype == np.float64 and array.shape == (61, 6)
    assert (array[0] == array[-1]).all()


@pytest.mark.parametrize("name", ACCEPTED)
def test_a_route_with_repeated_points_or_either_direction_loads_as_the_same_loop(route_files, name):
    track = tracks.load(route_files[name])
    plain = tracks.load(route_files["counterclockwise"])
    assert track.name == name
    assert len(track.centre) == 61  # 60 different waypoints and the closing one
    assert (track.centre[0] == track.centre[-1]).all()
    assert track.length == pytest.approx(plain.length)
    assert track.width == pytest.approx(routes.WIDTH, abs=0.001)


@pytest.mark.parametrize("name", sorted(REFUSED))
def test_a_route_deepracer_or_a_racer_could_not_drive_is_refused_in_plain_words(route_files, name):
    with pytest.raises(TrackError, match=REFUSED[name]):
        tracks.load(route_files[name])


def test_the_route_script_writes_its_files_from_the_command_line(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "tests.routes", str(tmp_path)],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    assert sorted(result.stdout.split()) == sorted(
        str(tmp_path / f"{n}.npy") for n in routes.ROUTES
    )
    np.testing.assert_array_equal(np.load(tmp_path / "clockwise.npy"), routes.clockwise())


def test_columns_past_the_sixth_are_left_aside_as_deepracer_does():
    array = routes.counterclockwise()
    wide = np.hstack([array, np.ones((len(array), 2))])
    track = tracks.load({"name": "wide", "route": wide})
    np.testing.assert_array_equal(track.centre, array[:, :2])


def test_a_repeated_point_is_dropped_keeping_the_first_as_deepracer_does():
    array = routes.repeated_point()
    track = tracks.load({"name": "dup", "route": array})
    np.testing.assert_array_equal(track.centre, np.delete(array, 21, axis=0)[:, :2])


def test_a_border_point_repeated_alone_keeps_its_waypoint():
    array = routes.repeated_border_point()
    track = tracks.load({"name": "dup", "route": array})
    np.testing.assert_array_equal(track.inner, array[:, 2:4])


def test_the_direction_is_read_from_the_file():
    assert tracks.load({"name": "a", "route": routes.counterclockwise()}).direction == (
        "counterclockwise"
    )
    assert tracks.load({"name": "b", "route": routes.clockwise()}).direction == "clockwise"


def test_a_clockwise_file_driven_counterclockwise_is_reversed_and_clockwise_is_kept():
    track = tracks.load({"name": "cw", "route": routes.clockwise()})
    assert track.with_direction("clockwise") is track
    ccw = track.with_direction("counterclockwise")
    assert ccw.direction == "counterclockwise"
    np.testing.assert_array_equal(ccw.centre, track.centre[::-1])
    assert tracks.signed_area(ccw.centre[:-1]) > 0
    # Driving counter-clockwise, the inner border (the one inside the loop) is on the left.
    point = ccw.point_at(3.0, 0.3)[:2]
    assert ccw.project(point)[2]
    # DeepRacer's is_reversed is its REVERSE_DIR: against the file's order, not "clockwise".
    assert not track.reversed and ccw.reversed


@pytest.mark.parametrize("direction, reversed_", [("clockwise", False), ("counterclockwise", True)])
def test_is_reversed_means_against_the_route_files_order(tmp_path, direction, reversed_):
    import gymnasium

    import simulator

    path = tmp_path / "cw_track.npy"
    np.save(path, routes.clockwise())
    env = gymnasium.make(simulator.ENV_ID, track=str(path), direction=direction)
    env.reset(seed=0)
    params = env.step(env.action_space.sample())[4]["params"]
    assert params["is_reversed"] is reversed_
    env.close()


def test_every_built_in_track_runs_counterclockwise_as_generated():
    for name in tracks.names(origin="pitlane"):
        assert tracks.load(name).direction == "counterclockwise"


def test_an_inline_track_loads_from_the_files_bytes_with_its_metadata():
    buffer = io.BytesIO()
    np.save(buffer, routes.clockwise())
    track = tracks.load(
        {
            "name": "reInvent2019_track",
            "display_name": "re:Invent 2019",
            "directions": ["clockwise"],
            "route": buffer.getvalue(),
            "difficulty": "advanced",
        }
    )
    assert (track.name, track.display_name, track.directions) == (
        "reInvent2019_track",
        "re:Invent 2019",
        ("clockwise",),
    )
    assert track.difficulty == "advanced"
    with pytest.raises(TrackError, match="cannot be driven counterclockwise"):
        track.with_direction("counterclockwise")


def test_bytes_that_are_not_a_route_file_are_refused():
    with pytest.raises(TrackError, match=r"The route file of x is not a NumPy \.npy track file"):
        tracks.load({"name": "x", "route": b"hello"})


def test_a_registered_resolver_lets_a_name_load_and_travel_inline():
    spec = {"name": "my-loop", "display_name": "My loop", "route": routes.counterclockwise()}

    def resolver(name):
        return spec if name == "my-loop" else None

    tracks.register_resolver(resolver)
    try:
        assert tracks.load("my-loop").display_name == "My loop"
        assert tracks.inline("my-loop")["name"] == "my-loop"
        assert tracks.inline("pitlane-oval") == "pitlane-oval"
        assert tracks.inline("monza") == "monza"
        with pytest.raises(TrackError, match="No track named 'monza'"):
            tracks.load("monza")
    finally:
        tracks.unregister_resolver(resolver)
    with pytest.raises(TrackError, match="No track named 'my-loop'"):
        tracks.load("my-loop")


def test_a_header_claiming_more_than_the_file_holds_is_refused_before_any_memory_is_set_aside():
    said = r"^The route file is cut short or damaged: its header says it holds "
    huge = said + r"6,000,000,000,000 values \(shape \(1000000000000, 6\)\)"
    with pytest.raises(TrackError, match=huge):
        tracks.read_route(claiming((10**12, 6)))
    one_row_more = said + r"366 values .* 2,928 bytes, and 2,880 bytes follow the header\.$"
    with pytest.raises(TrackError, match=one_row_more):
        tracks.read_route(claiming((61, 6)))
    assert tracks.read_route(claiming((60, 6))).shape == (60, 6)  # as its header says


def test_a_route_file_of_pickled_objects_is_refused_without_unpickling_them():
    buffer = io.BytesIO()
    np.save(buffer, np.array([object()] * 6, dtype=object), allow_pickle=True)
    with pytest.raises(TrackError, match=r"^The route file holds values that are not numbers\.$"):
        tracks.read_route(buffer.getvalue())
