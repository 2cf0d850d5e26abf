import pytest
from playwright.sync_api import Page, expect

from rl import hyperparameters
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from tests.helpers.training import TINY_PPO, settings
from training.models import TrainingJob
from training.services import model_create

pytestmark = pytest.mark.django_db(transaction=True)

# Many epochs on small batches: the car waits for its new policy long enough to look at it.
SLOW_LEARNER = {**hyperparameters.defaults("clipped_ppo"), **TINY_PPO, "num_epochs": 10}
FIRST_CAMERA_FRAME = """() => {
  const frame = document.querySelector("[data-live-frame]");
  new MutationObserver(() => {
    if (frame.dataset.view !== "camera" || window.firstCameraFrame) return;
    window.firstCameraFrame = {
      rate: document.querySelector("[data-live-rate]").textContent,
      moment: frame.dataset.moment,
    };
  }).observe(frame, { attributes: true, attributeFilter: ["data-seq"] });
}"""


def test_the_view_chosen_while_the_car_waits_shows_at_once_and_is_kept_on_reload(
    page: Page, alice, tracks, celery_worker_process
):
    model = model_create(
        owner=alice, settings=settings(name="view-oval", hyperparameters=SLOW_LEARNER)
    )
    page.goto("/accounts/login/", timeout=90_000)  # a server's first page can be slow to come
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/")
    frame = page.locator("[data-live-frame]")
    expect(frame).to_have_attribute("data-view", "spectator", timeout=90_000)

    # The episodes of the first iteration are in: the car waits while the policy is updated.
    rate = page.locator("[data-live-rate]")
    expect(rate).to_have_text("paused", timeout=180_000)
    waiting = frame.get_attribute("data-moment")

    # The car's own camera, chosen now, shows the car where it waits, not at the next episode.
    page.evaluate(FIRST_CAMERA_FRAME)
    page.locator("[data-live-view]").select_option("camera")
    first = page.wait_for_function("() => window.firstCameraFrame", timeout=10_000).json_value()
    assert first == {"rate": "paused", "moment": waiting}
    page.wait_for_function("() => document.querySelector('[data-live-frame]').naturalWidth === 160")

    # A new visit to the page keeps the choice (not the browser's restoring of a form).
    page.goto(f"/models/{model.pk}/")
    expect(page.locator("[data-live-view]")).to_have_value("camera")
    expect(frame).to_have_attribute("data-view", "camera", timeout=30_000)
    page.wait_for_function("() => document.querySelector('[data-live-frame]').naturalWidth === 160")

    page.get_by_role("button", name="Stop training").click()
    page.get_by_role("dialog").get_by_role("button", name="Stop training").click()
    section = page.locator("[data-live-url]")
    expect(section).to_have_attribute("data-job-status", "COMPLETED", timeout=60_000)
    assert TrainingJob.objects.get(model=model).status == TrainingJob.Status.COMPLETED
