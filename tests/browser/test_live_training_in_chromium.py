import pytest
from playwright.sync_api import Page, expect

from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import FRAME_BYTES, log_in
from tests.helpers.training import settings
from training.models import RLModel, TrainingJob
from training.services import model_create

pytestmark = pytest.mark.django_db(transaction=True)


def test_a_racer_watches_the_car_learn_and_stops_training(
    page: Page, alice, tracks, celery_worker_process
):
    model = model_create(owner=alice, settings=settings(name="live-oval"))
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/")
    section = page.locator("[data-live-url]")
    frame = page.locator("[data-live-frame]")

    # Frames arrive over the websocket, and they change as the car drives.
    expect(frame).to_be_visible(timeout=90_000)
    expect(section).to_have_attribute("data-job-status", "IN_PROGRESS")
    first = frame.evaluate(FRAME_BYTES)
    page.wait_for_function(
        "seq => Number(document.querySelector('[data-live-frame]').dataset.seq) > seq + 10",
        arg=int(frame.get_attribute("data-seq")),
    )
    assert frame.evaluate(FRAME_BYTES) != first
    size = frame.evaluate("img => [img.naturalWidth, img.naturalHeight]")
    assert size == [640, 480]

    # What the policy sees: the 160 x 120 camera.
    page.get_by_label("View").select_option("camera")
    expect(frame).to_have_attribute("data-view", "camera", timeout=10_000)
    page.wait_for_function("() => document.querySelector('[data-live-frame]').naturalWidth === 160")
    page.get_by_label("View").select_option("spectator")

    # The graph gets its points as iterations finish, without a reload.
    chart = page.locator("[data-live-chart]")
    # (Several cars a worker may have learnt more than one iteration by the time it is read.)
    page.wait_for_function(
        "() => Number(document.querySelector('[data-live-chart]').dataset.iterations) >= 1",
        timeout=120_000,
    )
    iterations = int(chart.get_attribute("data-iterations"))
    assert int(chart.get_attribute("data-points")) >= iterations * (5 + 2)  # episodes, averages
    assert page.locator("[data-live-iterations] tr").count() >= iterations
    expect(page.locator("[data-live-time]")).to_contain_text("left")

    page.get_by_role("button", name="Stop training").click()
    page.get_by_role("dialog").get_by_role("button", name="Stop training").click()
    expect(section).to_have_attribute("data-job-status", "COMPLETED", timeout=60_000)
    expect(page.locator("[data-live-status]")).to_have_text("Completed")
    expect(page.locator("[data-live-model-status]")).to_have_text("Ready")
    expect(page.get_by_role("link", name="Evaluate")).to_be_visible()
    expect(page.get_by_role("button", name="Stop training")).to_be_hidden()
    assert TrainingJob.objects.get(model=model).status == TrainingJob.Status.COMPLETED
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY
