"""The Analysis tab as a person sees it (issue 54): the iterations a re-scoring covers stand on
one line, each label with its input, on a laptop and on a phone; a car's steps far off the track
are drawn whole on the map, not cut off at its edge; and its lap times say they are training's."""

from __future__ import annotations

import pytest
from playwright.sync_api import Page, expect

from simulator.trace import to_csv
from tests.helpers.accounts import PASSWORD
from tests.helpers.analysis import HAND_WRITTEN, row, untrained
from tests.helpers.browser import log_in
from training import artifacts, signals

pytestmark = pytest.mark.django_db(transaction=True)

# A third episode that drives straight off the Pitlane Oval's right end, 9 m from its centre.
FAR_OFF = [
    row(2, 1, 0.5, -1.49, 0.0, 0.0, -1, 0.0, 0.0, 5, 10.4, "prepare"),
    row(2, 2, 4.5, -0.5, 0.0, 4.0, 2, 0.5, 2.0, 5, 10.4667, "in_progress"),
    row(2, 3, 9.0, 0.0, 0.0, 4.0, 2, 0.001, 3.5, 6, 10.5333, "off_track"),
]

# Which columns of the map's canvas hold anything but its white background, as "0" and "1".
DRAWN_COLUMNS = """canvas => {
  const { width, height } = canvas;
  const data = canvas.getContext("2d").getImageData(0, 0, width, height).data;
  const drawn = new Uint8Array(width);
  for (let y = 0; y < height; y += 1) {
    for (let x = 0; x < width; x += 1) {
      const i = 4 * (y * width + x);
      if (data[i] < 235 || data[i + 1] < 235 || data[i + 2] < 235) drawn[x] = 1;
    }
  }
  return drawn.join("");
}"""


def analysis_of_a_car_that_left_far(owner, page: Page) -> None:
    model = untrained(owner, "far-off")
    document = to_csv([*HAND_WRITTEN, *FAR_OFF])
    artifacts.save(model, artifacts.training_trace(1), document)
    signals.trace_recorded.send(
        type(model.jobs.get()), document=document, job=model.jobs.get(), iteration=1
    )
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/analysis/")
    expect(page.locator("[data-analysis]")).to_have_attribute("data-loaded", "1", timeout=30_000)


@pytest.mark.slow
def test_it_draws_the_steps_off_the_track_whole_and_keeps_each_iteration_input_by_its_label(
    page: Page, alice, tracks
):
    page.set_viewport_size({"width": 1366, "height": 850})
    analysis_of_a_car_that_left_far(alice, page)

    # The lone step 9 m out is on the canvas, apart from the track, with room to its right.
    columns = page.locator("[data-map]").evaluate(DRAWN_COLUMNS)
    last = columns.rfind("1")
    assert len(columns) - 1 - last >= 8, "a step is cut off at the map's right edge"
    before = columns[: last + 1].rstrip("1")
    assert len(before) - len(before.rstrip("0")) >= 20, "the far step is not apart from the track"

    # Its laps are training laps, as the model page's table names them ("Best training lap").
    laps = page.locator("[data-lap-chart]").evaluate(
        "canvas => Chart.getChart(canvas).legend.legendItems.map((item) => item.text)"
    )
    assert laps == ["Best training lap [s]", "Median training lap [s]"]

    first, last_label = page.locator("[data-score-range] label").all()
    inputs = page.locator("[data-score-range] input")
    expect(inputs.first).to_be_visible()
    expect(inputs.last).to_be_visible()
    one, two = first.bounding_box(), last_label.bounding_box()
    assert abs(one["y"] - two["y"]) < 2 and two["x"] > one["x"] + one["width"]  # one line

    page.set_viewport_size({"width": 390, "height": 844})
    expect(inputs.last).to_be_visible()
    for label in (first, last_label):
        box, field = label.bounding_box(), label.locator("input").bounding_box()
        assert box["height"] < 1.6 * field["height"], "a label and its input on two lines"
        assert box["x"] >= 0 and box["x"] + box["width"] <= 390
    assert page.evaluate("document.scrollingElement.scrollWidth") <= 390
