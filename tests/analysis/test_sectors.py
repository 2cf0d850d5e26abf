"""A complete lap against the racing line, sector by sector: a lap driven on the line at its
speeds loses nothing anywhere, one a tenth slower loses a tenth of each sector's time and is
flagged where it loses most; the line's sectors add up to its laps. The Analysis tab's page
brings the line for its map, and a lap's episode its sectors; a line still computing is said in
words."""

from __future__ import annotations

import numpy as np
import pytest
from django.urls import reverse

from analysis import sectors
from simulator import racing_line, tracks
from simulator.car import CarSpec
from tests.helpers.analysis import recorded_by_hand
from training import track_lines

STEP = 1 / 15  # [s] between a trace's rows
ACCELERATING = racing_line.Limits.of(CarSpec()).accelerating


@pytest.fixture(scope="module")
def oval():
    track = tracks.load("pitlane-oval")
    line = racing_line.stored_line(track)
    assert line is not None, "the Pitlane Oval's line is stored with the simulator"
    return track, line


def driven_on_the_line(track, line_lap: sectors.Lap, start: float, slower: float = 1.0):
    """A trace's lap on the line, a row every 1/15 s (``slower`` times the line's time), with
    the progress the simulator records: the centre line covered since ``start``."""
    total = line_lap.times[-1] * slower
    times = np.append(np.arange(0.0, total, STEP), total)
    along = np.interp(times / slower, line_lap.times, line_lap.distances)
    x = np.interp(along, line_lap.distances, line_lap.points[:, 0])
    y = np.interp(along, line_lap.distances, line_lap.points[:, 1])
    # As the simulator counts it: the centre line covered since the start, at most once round.
    along = track.project_points(np.column_stack([x, y])).distance
    moved = (np.diff(along) + track.length / 2) % track.length - track.length / 2
    covered = np.clip(np.concatenate([[0.0], np.cumsum(moved)]) / track.length, 0.0, 1.0)
    covered[-1] = 1.0  # the lap complete
    return sectors.recorded_lap(progress=100 * covered, tstamp=1000.0 + times, x=x, y=y)


@pytest.mark.parametrize(("start", "standing"), [(0.0, True), (0.35, True), (0.62, False)])
def test_a_lap_driven_on_the_line_at_its_speeds_loses_no_time_in_any_sector(oval, start, standing):
    track, line = oval
    on_line = sectors.line_lap(
        line, track, start=start, standing=standing, accelerating=ACCELERATING
    )
    table = sectors.sector_table(on_line, driven_on_the_line(track, on_line, start), track)
    assert len(table["rows"]) == 10
    assert [row["from"] for row in table["rows"]] == list(range(0, 100, 10))
    for row in table["rows"]:
        assert row["line"] > 0
        assert row["gap"] == pytest.approx(0.0, abs=0.005)
        assert row["lap_speed"] == pytest.approx(row["line_speed"], rel=0.02)
    assert table["gap_total"] == pytest.approx(0.0, abs=0.005)


def test_the_lines_sectors_add_up_to_its_standing_lap_and_its_flying_lap(oval):
    track, line = oval
    standing = sectors.line_lap(line, track, start=0.0, standing=True, accelerating=ACCELERATING)
    flying = sectors.line_lap(line, track, start=0.47, standing=False, accelerating=ACCELERATING)
    lap = driven_on_the_line(track, standing, 0.0)
    assert sectors.sector_table(standing, lap, track)["line_total"] == pytest.approx(
        line.standing_lap_time, abs=0.002
    )
    lap = driven_on_the_line(track, flying, 0.47)
    assert sectors.sector_table(flying, lap, track)["line_total"] == pytest.approx(
        line.lap_time, abs=0.002
    )
    # From rest, the first sector is the slow one; the rest are the flying lap's.
    first_standing = sectors.sector_table(standing, lap, track)["rows"][0]["line"]
    rolling = sectors.line_lap(line, track, start=0.0, standing=False, accelerating=ACCELERATING)
    assert first_standing > sectors.sector_table(rolling, lap, track)["rows"][0]["line"] + 0.1


def test_a_lap_a_tenth_slower_loses_a_tenth_of_each_sector_and_is_flagged_where_it_loses_most(
    oval,
):
    track, line = oval
    on_line = sectors.line_lap(line, track, start=0.0, standing=True, accelerating=ACCELERATING)
    table = sectors.sector_table(
        on_line, driven_on_the_line(track, on_line, 0.0, slower=1.1), track
    )
    for row in table["rows"]:
        assert row["gap"] == pytest.approx(0.1 * row["line"], abs=0.005)
        assert row["lap_speed"] == pytest.approx(row["line_speed"] / 1.1, rel=0.02)
    longest = max(range(10), key=lambda k: table["rows"][k]["line"])
    assert table["worst"] == longest
    assert len(table["worst_path"]) >= 5  # the line's points in that sector, for the map
    assert table["lap_total"] == pytest.approx(1.1 * table["line_total"], abs=0.005)
    assert table["gap_total"] == pytest.approx(0.1 * table["line_total"], abs=0.005)


def test_a_lap_faster_than_the_line_everywhere_flags_no_sector(oval):
    track, line = oval
    on_line = sectors.line_lap(line, track, start=0.0, standing=True, accelerating=ACCELERATING)
    table = sectors.sector_table(
        on_line, driven_on_the_line(track, on_line, 0.0, slower=0.9), track
    )
    assert all(row["gap"] < 0 for row in table["rows"])
    assert table["worst"] is None
    assert table["worst_path"] == []


@pytest.mark.django_db
@pytest.mark.usefixtures("tracks")
def test_the_page_draws_the_line_and_a_laps_episode_brings_its_sectors(alice, client, oval):
    _, line = oval
    job = recorded_by_hand(alice)  # on the Pitlane Oval: a lap from the start line, one off
    client.force_login(alice)
    base = reverse("analysis:model", args=[job.model.pk])
    page = client.get(base)
    drawn = page.context["overview"]["racing_line"]
    assert drawn["status"] == "ready" and drawn["standing_lap_time"] == round(
        line.standing_lap_time, 3
    )
    assert len(drawn["points"]) == (len(line.points) + 1) // 2
    assert b"data-racing-line>" in page.content and b"a flying lap in" in page.content

    lap = client.get(f"{base}episode.json?iteration=1&episode=0").json()
    table = lap["sectors"]
    assert len(table["rows"]) == 10 and table["standing"] is True
    assert table["line_total"] == pytest.approx(line.standing_lap_time, abs=0.01)
    assert table["lap_total"] == pytest.approx(lap["seconds"], abs=0.001)
    off = client.get(f"{base}episode.json?iteration=1&episode=1").json()
    assert off["sectors"] is None and "did not complete a lap" in off["sectors_note"]


@pytest.mark.django_db
@pytest.mark.usefixtures("tracks")
def test_a_line_still_computing_is_said_in_words_and_compares_no_lap(alice, client, monkeypatch):
    job = recorded_by_hand(alice)

    def computing(*, track, direction, margin_cm=0):
        geometry = tracks.load(track.name).with_direction(direction)
        return track_lines.LineShown(track, geometry, direction, margin_cm, "computing")

    monkeypatch.setattr(track_lines, "track_line", computing)
    client.force_login(alice)
    base = reverse("analysis:model", args=[job.model.pk])
    page = client.get(base)
    assert page.status_code == 200
    assert "The racing line is being computed" in page.content.decode()
    assert b"data-racing-line>" not in page.content  # no checkbox for a line not drawn
    lap = client.get(f"{base}episode.json?iteration=1&episode=0").json()
    assert lap["sectors"] is None and "being computed" in lap["sectors_note"]
