import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import ARTIFACTS, off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from tests.helpers.models import ready_model
from training import streams
from training.models import Iteration

pytestmark = pytest.mark.django_db(transaction=True)

PHONE = {"width": 390, "height": 844}
EPISODE_DATASETS = (3, 4, 5)  # reward, training completion, evaluation completion per episode

# For each dataset: its points that its clipping area cuts (a point at 100% on an axis that ends
# at 100% is cut in half by default), the look of its first point, and the legend's size.
CHART = """canvas => {
  const chart = Chart.getChart(canvas);
  const area = chart.chartArea;
  const datasets = chart.data.datasets.map((set, index) => {
    const meta = chart.getDatasetMeta(index);
    const clip = meta._clip;
    const top = clip.top === false ? -Infinity : area.top - clip.top;
    const cut = meta.data.filter((point) => {
      const reach = point.options.radius + point.options.borderWidth / 2;
      return point.y - reach < top - 0.5;
    }).length;
    const first = meta.data[0].options;
    const alpha = Number((first.backgroundColor.match(/[\\d.]+(?=\\s*\\)$)/) || [1])[0]);
    const rgba = first.backgroundColor.startsWith("rgba") || first.backgroundColor.includes("/");
    return { cut, radius: first.radius, alpha: rgba ? alpha : 1, points: meta.data.length };
  });
  return {
    datasets, legendHeight: chart.legend.height, height: chart.height,
    position: chart.options.plugins.legend.position,
    labels: chart.legend.legendItems.map((item) => item.text),
  };
}"""


def a_model_that_reached_the_finish(owner):
    """A model whose training completed laps: completions at 100% in training and evaluation."""
    model = ready_model(owner)
    job = model.jobs.get()
    for number in range(1, 5):
        Iteration.objects.create(
            job=job,
            number=number,
            reward=20.0 * number,
            completion=25.0 * number,
            evaluation_completion=25.0 * number,
            episodes=5,
            steps=500,
            wall_seconds=1.0,
            training_points=[
                [20.0 * number + k, min(100.0, 25.0 * number + 10 * k)] for k in (-4, -2, 0, 2, 4)
            ],
            evaluation_points=[min(100.0, 25.0 * number + k) for k in (-15, 15)],
        )
    job.iterations = 4
    job.save()
    return model


def test_the_graph_shows_whole_points_at_100_percent_and_a_compact_legend_on_a_phone(
    page: Page, alice, tracks
):
    model = a_model_that_reached_the_finish(alice)
    log_in(page, "alice", PASSWORD)
    page.set_viewport_size(PHONE)
    page.goto(f"/models/{model.pk}/")
    canvas = page.locator("[data-live-chart]")
    expect(canvas).to_have_attribute("data-iterations", "4", timeout=30_000)
    canvas.scroll_into_view_if_needed()

    chart = canvas.evaluate(CHART)
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    canvas.screenshot(path=ARTIFACTS / "training-graph-on-a-phone.png")

    for index, dataset in enumerate(chart["datasets"]):
        assert dataset["points"] > 0
        assert dataset["cut"] == 0, f"dataset {index} has points cut at the chart's edge"
    for index in EPISODE_DATASETS:  # the single episodes' dots stand out
        assert chart["datasets"][index]["radius"] >= 3
        assert chart["datasets"][index]["alpha"] >= 0.4
    # On a phone the legend keeps to a few short lines under the graph.
    assert chart["position"] == "bottom"
    assert chart["legendHeight"] <= 0.2 * chart["height"], chart
    assert max(len(label) for label in chart["labels"]) <= 20

    page.set_viewport_size({"width": 1280, "height": 800})
    page.wait_for_function(
        "canvas => Chart.getChart(canvas).options.plugins.legend.position === 'top'",
        arg=canvas.element_handle(),
    )
    wide = canvas.evaluate(CHART)
    assert "Average completion (evaluation)" in wide["labels"]


def test_where_the_newest_iterations_time_went_is_shown_beside_the_graph_and_follows_it(
    page: Page, alice, tracks
):
    model = a_model_that_reached_the_finish(alice)
    job = model.jobs.get()
    split = {"driving": 4.0, "transfer": 0.5, "update": 5.0, "saving": 0.4, "checks": 0.1}
    Iteration.objects.filter(job=job, number=4).update(
        wall_seconds=10.0, time_split=split, evaluation_seconds=3.2
    )
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/")
    shown = page.locator("[data-live-time-split]")
    expect(shown).to_contain_text("in iteration 4: 10.0 s")
    expect(shown.locator('[data-phase="update"]')).to_have_text("Policy update 5.0 s · 50%")
    expect(shown.locator('[data-phase="driving"]')).to_have_text("Driving 4.0 s · 40%")
    expect(shown).to_contain_text("Its evaluation drove 3.2 s beside the next iteration.")

    Iteration.objects.create(
        job=job,
        number=5,
        reward=100.0,
        completion=100.0,
        episodes=5,
        steps=500,
        wall_seconds=8.0,
        time_split={**dict.fromkeys(split, 0.0), "driving": 2.0, "update": 6.0},
    )
    off_the_loop(streams.announce_iteration, job.pk, 5)
    expect(shown).to_contain_text("in iteration 5: 8.0 s")
    expect(shown.locator('[data-phase="update"]')).to_have_text("Policy update 6.0 s · 75%")
    # The model's training has ended (issue 54): no evaluation of iteration 5 is to come.
    said = shown.locator("[data-split-evaluation]")
    expect(said).to_be_visible()
    expect(said).to_have_text("Training ended before its evaluation finished.")
