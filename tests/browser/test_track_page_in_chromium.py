"""A track's page in Chromium (issue 59): the racing line drawn on the map with its lap times as
stored, copied for a reward function as valid Python, and a line being computed shown once a
worker has it, without a reload by hand."""

import ast

import pytest
from playwright.sync_api import Page, expect

from simulator import racing_line
from simulator import tracks as simulator_tracks
from tests.browser.checks import page_problems
from tests.browser.conftest import off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import expect_seen, log_in
from training import track_lines
from training.models import Track, TrackLine

pytestmark = pytest.mark.django_db(transaction=True)


def test_a_racer_reads_a_tracks_racing_line_and_copies_it(page: Page, alice, tracks, daphne_server):
    page.context.grant_permissions(["clipboard-read", "clipboard-write"], origin=daphne_server)
    track = Track.objects.get(name="reInvent2019_track")
    stored = racing_line.stored_line(simulator_tracks.load(track.name))
    log_in(page, "alice", PASSWORD)
    page.goto("/models/")
    page.get_by_role("link", name=f"Its racing line on {track.display_name}").click()

    expect(page.get_by_role("heading", name=track.display_name, exact=True)).to_be_visible()
    shown = page.get_by_role("img", name=f"Map of {track.display_name}")
    expect_seen(shown)
    box = shown.bounding_box()
    assert box["width"] >= 400 and box["height"] >= 200
    for band in page.locator("[data-line-band]").all():  # every band drawn inside the map
        drawn = band.bounding_box()
        assert drawn["width"] > 0 and drawn["x"] >= box["x"] - 1 and drawn["y"] >= box["y"] - 1
        assert drawn["x"] + drawn["width"] <= box["x"] + box["width"] + 1
    expect(page.locator("[data-line-legend] li")).to_have_count(len(track_lines.SPEED_COLOURS))
    expect(page.locator("[data-line-lap]")).to_have_text(f"{stored.lap_time:.2f} s")
    expect(page.locator("[data-line-standing-lap]")).to_have_text(
        f"{stored.standing_lap_time:.2f} s"
    )

    copy = page.get_by_role("button", name="Copy for a reward function")
    copy.scroll_into_view_if_needed()
    expect_seen(copy)
    copy.click()
    expect(page.locator("[data-copy-status]")).to_contain_text("Copied")
    copied = page.evaluate("navigator.clipboard.readText()")
    (assignment,) = [n for n in ast.parse(copied).body if isinstance(n, ast.Assign)]
    assert len(ast.literal_eval(assignment.value)) == len(stored.points[::2])
    page.set_viewport_size({"width": 390, "height": 844})  # a phone
    assert page_problems(page) == []


def test_a_line_being_computed_shows_itself_once_a_worker_has_it(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/tracks/rookie-loop/")
    page.get_by_label("Margin inside the borders").select_option("10 cm")
    page.get_by_role("button", name="Show this line").click()
    expect(page.get_by_text("This line is being computed")).to_be_visible()

    row = TrackLine.objects.get(margin_cm=10)
    off_the_loop(track_lines.track_line_compute, line_id=row.pk)  # the worker's part
    row.refresh_from_db()
    expect(page.locator("[data-line-lap]")).to_have_text(f"{row.lap_time:.2f} s")
    expect(page.get_by_label("Margin inside the borders")).to_have_value("10")
