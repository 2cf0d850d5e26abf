"""DeepRacer's catalogue as built-in tracks: one track a console track, each direction on the route
file DeepRacer drives that way, every WORLD_NAME resolving (data/deepracer/, its NOTICE)."""

import json

import cv2
import gymnasium
import numpy as np
import pytest

import simulator
from simulator import tracks
from simulator.tracks import DEEPRACER_DIR, TrackError
from simulator.tracks.deepracer import difficulty, track_meta


def route(world_name: str) -> np.ndarray:
    return np.load(DEEPRACER_DIR / "routes" / f"{world_name}.npy")


def test_the_catalogue_holds_every_looped_route_file_of_simapp_as_70_tracks():
    shipped = sorted(path.stem for path in (DEEPRACER_DIR / "routes").glob("*.npy"))
    worlds = sorted(
        w for name in tracks.names(origin="deepracer") for w in tracks.entry(name)["world_names"]
    )
    assert len(shipped) == 126 and worlds == shipped  # simapp's 127 less Straight_track (open)
    assert len(tracks.names(origin="deepracer")) == 70  # the console's 62 and 8 it never listed
    assert tracks.names()[:2] == ["rookie-loop", "pitlane-oval"]  # ours first, as before


@pytest.mark.parametrize(
    ("world_name", "name", "direction", "driven"),
    [("2022_april_open", "2022_april_open", "counterclockwise", "2022_april_open_ccw"),
     ("2022_april_open_ccw", "2022_april_open", "counterclockwise", "2022_april_open_ccw"),
     ("2022_april_open_cw", "2022_april_open", "clockwise", "2022_april_open_cw"),
     ("reInvent2019_wide_ccw", "reInvent2019_wide", "counterclockwise", "reInvent2019_wide_ccw"),
     ("Albert", "Albert", "clockwise", "Albert"),
     ("reinvent_carpet", "reinvent_carpet", "counterclockwise", "reinvent_carpet")],
)  # fmt: skip
def test_a_world_name_resolves_to_its_track_and_the_direction_its_file_runs(
    world_name, name, direction, driven
):
    """A WORLD_NAME resolves to its track and the way its file runs; the track driven that way
    is on the route file the console drives (X_ccw/X_cw). For a bare name, which DeepRacer for
    Cloud writes, that is not always the file simapp drove (reInvent2019_track.npy holds 154
    waypoints, reInvent2019_track_ccw.npy 79): an import keeps that file (``on_route``, below)."""
    assert tracks.world(world_name) == (name, direction)
    loaded = tracks.load(world_name).with_direction(direction)
    assert (loaded.name, loaded.direction, loaded.world_name) == (name, direction, driven)
    assert not loaded.reversed


def test_a_name_that_is_no_route_file_resolves_to_nothing():
    assert tracks.world("rookie-loop") is None
    assert tracks.world("Straight_track") is None
    with pytest.raises(TrackError, match="and DeepRacer's 70 by their WORLD_NAME"):
        tracks.load("monza")


def test_each_direction_drives_the_route_file_deepracer_drives_that_way():
    track = tracks.load("2022_april_open")
    assert (track.display_name, track.direction) == ("Ace Speedway", "counterclockwise")
    np.testing.assert_array_equal(track.centre, route("2022_april_open_ccw")[:, :2])
    clockwise = track.with_direction("clockwise")
    assert (clockwise.world_name, clockwise.reversed) == ("2022_april_open_cw", False)
    np.testing.assert_array_equal(clockwise.centre, route("2022_april_open_cw")[:, :2])
    assert clockwise.with_direction("counterclockwise").world_name == "2022_april_open_ccw"


def test_a_track_held_to_one_route_file_drives_that_file_backwards_the_other_way():
    """What a model imported with a bare WORLD_NAME drives (RLModel.world_name), as simapp
    drives it: the file named, reversed by REVERSE_DIR, never the console's file that way."""
    held = tracks.load("reInvent2019_track").on_route("reInvent2019_track")
    assert (held.world_name, held.direction, len(held.waypoints)) == (
        "reInvent2019_track",
        "counterclockwise",
        154,
    )
    backwards = held.with_direction("clockwise")
    assert (backwards.world_name, backwards.reversed, len(backwards.waypoints)) == (
        "reInvent2019_track",
        True,
        154,
    )
    from_file = tracks.load(DEEPRACER_DIR / "routes" / "reInvent2019_track.npy")
    np.testing.assert_array_equal(held.centre, from_file.centre)
    np.testing.assert_array_equal(backwards.centre, held.centre[::-1])
    env = gymnasium.make(
        simulator.ENV_ID,
        track="reInvent2019_track",
        direction="clockwise",
        route="reInvent2019_track",
    )
    driven = env.unwrapped.track
    assert (driven.world_name, driven.direction) == ("reInvent2019_track", "clockwise")
    np.testing.assert_array_equal(driven.centre, backwards.centre)
    with pytest.raises(TrackError, match="2022_april_open_cw is not one of Smile Speedway's"):
        held.on_route("2022_april_open_cw")


def test_the_console_default_direction_comes_first():
    assert tracks.load("reInvent2019_wide").directions == ("clockwise", "counterclockwise")
    assert tracks.load("reInvent2019_wide").world_name == "reInvent2019_wide_cw"


def test_a_one_way_console_track_refuses_the_other_way_in_the_racers_words():
    with pytest.raises(TrackError, match=r"^Yun Speedway cannot be driven counterclockwise"):
        tracks.load("Albert").with_direction("counterclockwise")


def test_a_route_the_console_never_listed_is_driven_either_way_by_reversing_it():
    carpet = tracks.load("reinvent_carpet")
    assert carpet.display_name == "re:Invent 2018 (Carpet)"  # deepracer-utils' track_meta
    clockwise = carpet.with_direction("clockwise")
    assert clockwise.reversed and clockwise.world_name == "reinvent_carpet"
    np.testing.assert_array_equal(clockwise.centre, carpet.centre[::-1])


def test_seasons_come_from_deepracer_utils_and_ours_have_none():
    seasons = {name: tracks.entry(name)["season"] for name in tracks.names()}
    assert seasons["2024_reinvent_champ"] == 2024
    assert seasons["penbay_pro"] == 2021
    assert seasons["reinvent_base"] == 2019  # "2019 and earlier"
    assert seasons["rookie-loop"] is None
    assert set(seasons.values()) == {None, 2019, 2020, 2021, 2022, 2024}


def test_lengths_and_widths_are_measured_from_the_route_files():
    entry = tracks.entry("2022_october_open")  # the console says width 1.07 here, 107 elsewhere
    track = tracks.load("2022_october_open")
    assert entry["length_m"] == round(track.length, 2) == 49.53
    assert entry["width_m"] == round(track.width, 3) == 1.067


def test_every_deepracer_track_has_a_small_preview_and_the_licences_lie_beside_the_data():
    for name in tracks.names(origin="deepracer"):
        assert cv2.imread(str(tracks.preview_path(name))).shape[1] == 240, name
    notice = (DEEPRACER_DIR / "NOTICE").read_text()
    for commit in (
        "01f5f015fd852f952b351643898d4beb4f36494b",  # simapp
        "61af778f9b1d904a6318b746fc3e5a8ddac525ce",  # deepracer-on-aws
        "262e3fe37abe8706dc2fa1901e7d046e46b39709",
    ):  # deepracer-utils
        assert commit in notice
    assert "Apache License" in (DEEPRACER_DIR / "LICENSE-Apache-2.0.txt").read_text()
    assert (
        "Permission is hereby granted"
        in (DEEPRACER_DIR / "LICENSE-MIT-0-deepracer-utils.txt").read_text()
    )


def test_the_importer_reads_names_and_seasons_from_track_meta_and_buckets_difficulty():
    source = """
# 2022 tracks
track_meta["2022_april_open"] = "Ace Speedway"
# 2019 and earlier tracks
track_meta["reinvent_base"] = "re:Invent 2018"
"""
    assert track_meta(source) == {
        "2022_april_open": ("Ace Speedway", 2022),
        "reinvent_base": ("re:Invent 2018", 2019),
    }
    assert [difficulty(s) for s in (10, 25, 50, 94)] == [
        "beginner",
        "intermediate",
        "advanced",
        "expert",
    ]


def test_the_catalogue_file_names_a_route_file_for_every_direction_or_reverses_its_own():
    for entry in json.loads((DEEPRACER_DIR / "catalog.json").read_text()):
        for direction, world_name in entry["routes"].items():
            assert entry["world_names"][world_name] == direction
        if len(entry["routes"]) < len(entry["directions"]):
            assert not entry["console"]  # the 8 the console never listed


@pytest.mark.parametrize(
    ("name", "direction", "said"),
    [("2022_april_open", "clockwise", ("2022_april_open_cw", False)),
     ("2022_april_open", "counterclockwise", ("2022_april_open_ccw", False)),
     ("Albert", "clockwise", ("Albert", False)),  # its file runs clockwise
     ("reinvent_carpet", "clockwise", ("reinvent_carpet", True)),
     ("pitlane-oval", "clockwise", ("pitlane-oval", True))],
)  # fmt: skip
def test_a_track_and_direction_are_written_as_deepracer_names_them(name, direction, said):
    assert tracks.deepracer_world(name, direction) == said
    world_name, reverse = said
    # and read back, as an import reads training_params.yaml: the same track, the same way
    back = tracks.load(world_name).with_direction(direction)
    assert (back.name, back.reversed) == (name, reverse)
