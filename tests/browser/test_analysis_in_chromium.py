"""The Analysis tab in Chromium: a trained model's driving on the track, coloured and filtered,
with the racing line and the fastest lap against it sector by sector, one episode followed step
by step, and another reward function scored by a real worker."""

from __future__ import annotations

import pytest
from playwright.sync_api import Page, expect

from simulator import racing_line as simulator_racing_line
from simulator import tracks as simulator_tracks
from tests.browser.conftest import ARTIFACTS
from tests.helpers.accounts import PASSWORD
from tests.helpers.analysis import SPEED_AND_OFF_TRACK, untrained
from tests.helpers.browser import log_in
from tests.helpers.training_logs import train_on_paper
from training.models import RewardFunction

pytestmark = pytest.mark.django_db(transaction=True)

# How many of the map's pixels are the racing line's pink (#ff2e93), give or take blending.
PINK = """canvas => {
  const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
  let found = 0;
  for (let i = 0; i < data.length; i += 4) {
    if (data[i] > 220 && data[i + 1] < 110 && data[i + 2] > 110 && data[i + 2] < 190) found += 1;
  }
  return found;
}"""

# How many different colours the map's canvas holds: a drawn track and coloured steps give many.
COLOURS = """canvas => {
  const data = canvas.getContext("2d").getImageData(0, 0, canvas.width, canvas.height).data;
  const seen = new Set();
  const step = 4 * 97;
  for (let i = 0; i < data.length; i += step) seen.add(`${data[i]},${data[i + 1]},${data[i + 2]}`);
  return seen.size;
}"""


def test_a_racer_reads_their_models_driving_and_tries_another_reward_function(
    page: Page, alice, tracks, celery_worker_process
):
    model = untrained(alice, "analysed")
    RewardFunction.objects.create(
        owner=alice, name="speed-and-off-track", source=SPEED_AND_OFF_TRACK
    )
    train_on_paper(model)  # two iterations: laps, and episodes straight off the track
    errors: list[str] = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/")
    page.get_by_role("link", name="Analysis").click()
    root = page.locator("[data-analysis]")
    expect(root).to_have_attribute("data-loaded", "1", timeout=30_000)
    expect(page.locator("[data-map-caption]")).to_contain_text("where a car left the track (4)")
    expect(page.locator("[data-fastest]")).to_contain_text("Fastest picked: iteration")
    canvas = page.locator("[data-map]")
    assert canvas.evaluate(COLOURS) > 8
    expect(page.locator("[data-episode-count]")).to_contain_text("8 episodes")

    # The racing line on the map, and the fastest lap against it sector by sector: the line's
    # sectors add up to its lap from a standing start, as the page states it and as stored.
    racing_line = page.get_by_label("Racing line")
    expect(racing_line).to_be_visible()
    expect(racing_line).to_be_checked()
    assert canvas.evaluate(PINK) > 50
    stated = page.locator("[data-racing-line-status]")
    expect(stated).to_be_visible()
    stored = simulator_racing_line.stored_line(simulator_tracks.load("pitlane-oval"))
    standing = float(stated.locator("[data-line-standing-lap]").inner_text())
    assert standing == pytest.approx(stored.standing_lap_time, abs=0.005)
    sectors = page.locator("[data-sector-table]")
    expect(sectors).to_be_visible()
    expect(sectors.locator("tbody tr")).to_have_count(10)
    expect(page.locator("[data-sectors-caption]")).to_contain_text("The fastest picked lap")
    total = sectors.locator("[data-sector-total-line]").inner_text()
    assert float(total.removesuffix(" s")) == pytest.approx(standing, abs=0.01)
    expect(sectors.locator(".sector-worst")).to_have_count(1)
    expect(sectors.locator(".sector-worst")).to_contain_text("where speed is lost")
    page.locator("[data-sectors]").screenshot(path=ARTIFACTS / "analysis-sectors.png")
    canvas.screenshot(path=ARTIFACTS / "analysis-racing-line.png")
    racing_line.uncheck()
    expect(page.locator("[data-map-caption]")).not_to_contain_text("pink")
    assert canvas.evaluate(PINK) == 0
    racing_line.check()
    # A lap followed on the map is the one compared.
    laps = page.locator("[data-episode-table] tbody tr", has_text="Lap complete")
    laps.first.get_by_role("button", name="Show").click()
    expect(page.locator("[data-sectors-caption]")).to_contain_text("The followed lap")
    expect(sectors.locator("tbody tr")).to_have_count(10)
    page.get_by_role("button", name="Back to all steps").click()
    expect(page.locator("[data-sectors-caption]")).to_contain_text("The fastest picked lap")
    with page.expect_download() as saved:
        page.locator('[data-download="map"]').click()
    assert saved.value.suggested_filename.endswith("-map.png")
    assert saved.value.path().read_bytes().startswith(b"\x89PNG")

    # Colour by speed: the legend's scale is in m/s; by action: a label per action.
    page.get_by_label("Colour by").select_option("speed")
    expect(page.locator("[data-map-legend]")).to_contain_text("m/s")
    page.get_by_label("Colour by").select_option("action")
    expect(page.locator("[data-map-legend]")).to_contain_text("0: ")

    # Only the episodes that left the track, of iteration 2.
    page.get_by_label("Lap complete").uncheck()
    page.get_by_label("From iteration", exact=True).fill("2")
    page.get_by_label("From iteration", exact=True).dispatch_event("change")
    expect(page.locator("[data-episode-count]")).to_contain_text("2 episodes")
    rows = page.locator("[data-episode-table] tbody tr")
    expect(rows).to_have_count(2)
    assert set(rows.evaluate_all("rows => rows.map((r) => r.dataset.iteration)")) == {"2"}
    expect(sectors).to_be_hidden()  # no lap picked: nothing to compare with the line
    expect(page.locator("[data-sectors-caption]")).to_contain_text("No lap was completed")

    # One episode, step by step: its params at each.
    rows.first.get_by_role("button", name="Show").click()
    viewer = page.locator("[data-episode-viewer]")
    expect(viewer).to_be_visible()
    expect(viewer).to_contain_text("Off track")
    expect(viewer.locator("[data-episode-params]")).to_contain_text("distance_from_center")
    slider = viewer.locator("[data-episode-step]")
    last = slider.get_attribute("max")
    slider.fill(last)
    expect(viewer.locator("[data-episode-step-label]")).to_contain_text("(off_track)")
    canvas.screenshot(path=ARTIFACTS / "analysis-one-episode.png")
    viewer.get_by_role("button", name="Back to all steps").click()

    # Another reward function, from the racer's library, scored by the simulation worker. The
    # editor opens on the model's own; choosing fills it, typing makes it pasted code again.
    editor, start_from = page.get_by_label("Reward function"), page.get_by_label("Start from")
    expect(start_from).to_have_value("model")
    expect(editor).to_have_value(model.reward_function)
    start_from.select_option(label="speed-and-off-track")
    expect(editor).to_have_value(SPEED_AND_OFF_TRACK)
    editor.press("End")
    editor.press("Space")
    expect(start_from).to_have_value("")
    start_from.select_option(label="speed-and-off-track")
    page.get_by_role("button", name="Score the recorded driving").click()
    expect(page.locator("[data-rescore-status]")).to_contain_text("Scored", timeout=60_000)
    expect(page.get_by_label("Colour by")).to_have_value("rescored")
    expect(page.locator("[data-rescored-column]")).to_be_visible()
    expect(page.locator("[data-rescore-figure]")).to_be_visible()
    first_rescored = rows.first.locator("td").nth(8)
    expect(first_rescored).not_to_have_text("—")
    page.screenshot(path=ARTIFACTS / "analysis-rescored.png", full_page=True)

    # No outcome ticked: nothing is picked, and the page says so.
    for box in page.locator("[data-outcome]").all():
        box.uncheck()
    expect(page.locator("[data-episode-count]")).to_contain_text("0 episodes")
    expect(rows).to_have_count(0)
    assert errors == []

    # A phone: nothing wider than the screen.
    page.set_viewport_size({"width": 390, "height": 844})
    page.reload()
    expect(root).to_have_attribute("data-loaded", "1", timeout=30_000)
    assert page.evaluate("document.documentElement.scrollWidth") <= 391
    assert canvas.evaluate(COLOURS) > 8
