"""A track's page and its racing line (issue 59): the stored line of a built-in track drawn with
its lap times, the literal a reward function pastes, and the lines a worker computes (an added
track's, a margin's) requested once, computed again when stale."""

import ast
import re

import numpy as np
import pytest
from django.urls import reverse

from simulator import racing_line
from simulator import tracks as simulator_tracks
from tests import routes
from tests.services import wait_for
from training import rewards, track_lines
from training.models import Track, TrackLine
from training.rewards import reward_validate
from training.services import track_add

pytestmark = pytest.mark.django_db


def page(client, name: str, **query):
    return client.get(reverse("training:track-detail", args=[name]), query)


def literal_of(response) -> str:
    text = response.content.decode()
    found = re.search(r"<textarea[^>]*data-line-literal>(.*?)</textarea>", text, re.DOTALL)
    assert found, "the page has no literal to copy"
    return found.group(1).replace("&quot;", '"').replace("&#x27;", "'")


def racing_line_of(literal: str) -> list[list[float]]:
    """What a reward function that pastes ``literal`` reads: the RACING_LINE it assigns."""
    (assignment,) = [n for n in ast.parse(literal).body if isinstance(n, ast.Assign)]
    assert [target.id for target in assignment.targets] == ["RACING_LINE"]
    return ast.literal_eval(assignment.value)


def test_a_built_in_tracks_page_shows_its_stored_line_its_lap_times_and_the_literal(
    client, alice, tracks
):
    client.force_login(alice)
    response = page(client, "reInvent2019_track")
    assert response.status_code == 200
    geometry = simulator_tracks.load("reInvent2019_track")
    stored = racing_line.stored_line(geometry)
    text = response.content.decode()
    assert f"{stored.lap_time:.2f} s" in text and f"{stored.standing_lap_time:.2f} s" in text
    assert text.count("data-line-band") >= 5  # drawn in bands of speed
    points = racing_line_of(literal_of(response))
    # Every second point, in the track's own coordinates, with its speed.
    assert len(points) == len(stored.points[:: track_lines.LITERAL_STRIDE])
    np.testing.assert_allclose(
        np.array(points), np.column_stack([stored.points, stored.speeds])[::2], atol=0.006
    )
    assert not TrackLine.objects.exists()  # read from the simulator's file, not computed


def test_a_pasted_literal_runs_unchanged_in_the_sandboxs_reward_function(client, alice, tracks):
    client.force_login(alice)
    literal = literal_of(page(client, "rookie-loop", direction="clockwise"))
    count = len(racing_line_of(literal))
    source = literal + "\n\ndef reward_function(params):\n    return float(len(RACING_LINE))\n"
    checked = reward_validate(source=source, track="rookie-loop", direction="clockwise")
    assert checked.errors == []
    assert {sample.reward for sample in checked.samples} == {float(count)}


def test_a_bad_margin_is_refused_in_words_and_the_page_still_shows_a_line(client, alice, tracks):
    client.force_login(alice)
    response = page(client, "rookie-loop", margin="7", direction="sideways")
    assert response.status_code == 400
    text = response.content.decode()
    assert "Choose a margin of 0, 5, 10, 15 or 20 cm." in text
    assert "Choose a direction this track is driven in." in text
    assert "data-line-lap" in text  # the default line, meanwhile


def test_a_margin_is_computed_by_a_worker_once_and_costs_time(
    client, alice, tracks, django_capture_on_commit_callbacks
):
    client.force_login(alice)
    with django_capture_on_commit_callbacks() as sent:
        response = page(client, "rookie-loop", margin="15")
        again = page(client, "rookie-loop", margin="15")  # asked twice while computing
    assert "is being computed" in response.content.decode()
    assert "is being computed" in again.content.decode()
    row = TrackLine.objects.get()
    assert (row.direction, row.margin_cm, row.status) == ("counterclockwise", 15, "computing")
    assert len(sent) == 1  # one task sent, not one a look

    track_lines.track_line_compute(line_id=row.pk)  # as the worker the task reaches does

    response = page(client, "rookie-loop", margin="15")
    row.refresh_from_db()
    assert row.status == "ready" and f"{row.standing_lap_time:.2f} s" in response.content.decode()
    stored = racing_line.stored_line(simulator_tracks.load("rookie-loop"))
    assert row.lap_time > stored.lap_time  # less room, a slower lap
    assert len(racing_line_of(literal_of(response))) == len(row.array[::2])


def test_a_line_computed_from_another_car_or_method_is_computed_again(
    client, alice, tracks, django_capture_on_commit_callbacks
):
    client.force_login(alice)
    track = Track.objects.get(name="rookie-loop")
    row = TrackLine.objects.create(
        track=track,
        direction="counterclockwise",
        margin_cm=5,
        key="an older method",
        status="ready",
        points=np.zeros((10, 3), np.float32).tobytes(),
        lap_time=1.0,
        standing_lap_time=1.0,
        requested_at="2026-01-01T00:00Z",
    )
    with django_capture_on_commit_callbacks() as sent:
        response = page(client, "rookie-loop", margin="5")
    assert "is being computed" in response.content.decode() and len(sent) == 1
    row.refresh_from_db()
    assert row.status == "computing" and row.key != "an older method"


def test_an_added_tracks_lines_are_requested_when_it_is_added(
    client, alice, tracks, django_capture_on_commit_callbacks
):
    with django_capture_on_commit_callbacks() as sent:
        track = track_add(
            name="H_track",
            display_name="H track",
            route=routes.route_bytes("clockwise"),
            directions=["counterclockwise", "clockwise"],
        )
    rows = TrackLine.objects.filter(track=track).order_by("direction")
    assert [(row.direction, row.status) for row in rows] == [
        ("clockwise", "computing"),
        ("counterclockwise", "computing"),
    ]
    assert len(sent) == 2
    track_lines.track_line_compute(line_id=rows[0].pk)  # the clockwise one, as a worker would
    client.force_login(alice)
    response = page(client, "H_track", direction="clockwise")
    text = response.content.decode()
    clockwise = TrackLine.objects.get(track=track, direction="clockwise")
    assert f"{clockwise.lap_time:.2f} s" in text
    assert "DeepRacer's own" not in text  # an added track's coordinates are its route file's


def test_an_unknown_track_has_no_page(client, alice):
    client.force_login(alice)
    assert page(client, "monza").status_code == 404


@pytest.mark.django_db(transaction=True)
def test_a_worker_computes_an_added_tracks_line(alice, tracks, celery_worker_process):
    track = track_add(
        name="O_track",
        display_name="O track",
        route=routes.route_bytes("clockwise"),
        directions=["clockwise"],
    )
    row = TrackLine.objects.get(track=track)

    def computed() -> bool:
        row.refresh_from_db()
        return row.status != "computing"

    wait_for(computed, "a worker to compute the racing line", timeout=120)
    assert row.status == "ready" and row.message == ""
    geometry = simulator_tracks.load("O_track").with_direction("clockwise")
    assert row.key == racing_line.line_key(geometry, racing_line.CarSpec(), 0.0)
    assert 0 < row.lap_time < row.standing_lap_time


def test_the_reward_editors_example_holds_the_stored_line_it_names(tracks):
    example = (rewards.EXAMPLES_DIR / "follow_racing_line.py").read_text()
    track = Track.objects.get(name="reInvent2019_track")
    shown = track_lines.track_line(track=track, direction="counterclockwise")
    assert track_lines.reward_literal(shown) in example  # regenerate the example when it differs


def test_the_example_with_a_tracks_line_pasted_pays_for_its_place_speed_heading_and_steady_hands(
    tracks,
):
    track = Track.objects.get(name="rookie-loop")
    shown = track_lines.track_line(track=track, direction="counterclockwise")
    source = track_lines.with_racing_line(rewards.example_source("follow_racing_line"), shown)
    assert track_lines.reward_literal(shown) in source and "reInvent2019" not in source
    assert reward_validate(source=source, track="rookie-loop").errors == []

    namespace = {}
    exec(compile(source, "follow_racing_line.py", "exec"), namespace)  # noqa: S102 (ours)
    stride = track_lines.LITERAL_STRIDE  # the points the literal holds
    line, speeds = shown.line.points[::stride], shown.line.speeds[::stride]
    k = int(np.argmin(speeds))  # the slowest point, in the tightest bend
    (x, y), (nx, ny) = line[k], line[k + 1]
    heading = np.degrees(np.arctan2(ny - y, nx - x))
    normal = np.array([y - ny, nx - x]) / np.hypot(nx - x, ny - y)
    width = 0.76  # [m] params["track_width"] as DeepRacer's tracks give it
    on_line = {
        "x": x, "y": y, "heading": heading, "speed": speeds[k] / 1.029, "track_width": width,
        "steering_angle": 0.0, "is_offtrack": False, "all_wheels_on_track": True,
    }  # fmt: skip

    def reward(steps: int, **changed) -> float:
        return namespace["reward_function"]({**on_line, "steps": steps, **changed})

    assert reward(1) == pytest.approx(1.0, abs=0.01)
    assert reward(2, speed=on_line["speed"] / 2) == pytest.approx(0.25, abs=0.01)
    assert reward(3, speed=on_line["speed"] + 1.0) < 0.01  # too fast into the bend
    aside = np.array([x, y]) + normal * 0.3 * width
    assert reward(4, x=aside[0], y=aside[1]) < 0.05
    assert reward(5, heading=heading + 30) < 0.01
    assert reward(6, steering_angle=15.0) == pytest.approx(0.75, abs=0.01)  # hands shaken
    assert reward(8, steering_angle=15.0) == pytest.approx(1.0, abs=0.01)  # a new episode
    assert reward(9, is_offtrack=True) < 0.01


def test_a_track_gone_from_the_catalogue_is_a_404_not_a_500(client, alice, tracks):
    Track.objects.create(
        name="retired", display_name="Retired", difficulty="beginner", length_m=20, width_m=1
    )
    client.force_login(alice)
    assert page(client, "retired").status_code == 404
    assert (
        track_lines.line_times(track=Track.objects.get(name="retired"), direction="clockwise")
        is None
    )
