"""The training clock and the stop, in the browser: the page counts on from the server's word
(it does not start again from the last measurement when it loads), two tabs agree, and "Stop
training" asks first, then the clock stops and the page says what it waits for."""

from datetime import timedelta

import pytest
from django.utils import timezone
from playwright.sync_api import Page, expect

from tests.helpers import training as training_helpers
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from training.models import TrainingJob

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.usefixtures("tracks")]

SHOWN = "() => Number(document.querySelector('[data-live-time]').dataset.shownSeconds)"


def training_job(owner, *, seconds: float, ago: float) -> TrainingJob:
    """A job in progress whose trainer, busy learning, last measured ``seconds`` ``ago``."""
    return training_helpers.training_job(
        owner, seconds=seconds, ago=ago, lease_expires=timezone.now() + timedelta(minutes=5)
    )


def samples(page: Page, count: int = 8) -> list[float]:
    taken = []
    for _ in range(count):
        taken.append(page.evaluate(SHOWN))
        page.wait_for_timeout(400)
    return taken


def test_the_clock_counts_on_from_the_servers_word_and_two_tabs_agree(page: Page, alice):
    job = training_job(alice, seconds=50, ago=100)
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{job.model_id}/")
    time = page.locator("[data-live-time]")
    expect(time).to_contain_text("used of 10 min")
    shown = samples(page)  # over the moment the live state arrives
    assert shown[0] >= 150, f"the page started from the last measurement: {shown}"
    assert shown == sorted(shown), f"the clock went back: {shown}"
    assert shown[-1] > shown[0]  # it runs

    other = page.context.new_page()
    other.goto(f"/models/{job.model_id}/")
    expect(other.locator("[data-live-time]")).to_contain_text("used of 10 min")
    other.wait_for_timeout(1500)
    first, second = page.evaluate(SHOWN), other.evaluate(SHOWN)
    assert abs(first - second) < 1.0
    other.close()


def test_stop_training_asks_first_then_the_clock_stops(page: Page, alice):
    job = training_job(alice, seconds=120, ago=0)
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{job.model_id}/")
    dialog = page.get_by_role("dialog")

    page.get_by_role("button", name="Stop training").click()
    expect(dialog).to_be_visible()
    expect(dialog).to_contain_text("the model keeps the weights of its last finished iteration")
    expect(dialog).to_contain_text("(iteration 3)")
    expect(dialog).to_contain_text("billed for the time used up to the stop")
    dialog.get_by_role("button", name="Keep training").click()
    expect(dialog).to_be_hidden()
    assert TrainingJob.objects.get(pk=job.pk).status == TrainingJob.Status.IN_PROGRESS

    page.get_by_role("button", name="Stop training").click()
    dialog.get_by_role("button", name="Stop training").click()
    expect(page.locator("[data-live-status]")).to_have_text(
        "Stopping · Saving the model from iteration 3"
    )
    expect(page.get_by_role("button", name="Stop training")).to_be_hidden()  # asked once
    expect(page.locator("[data-live-time]")).not_to_contain_text("left")
    stopped = TrainingJob.objects.get(pk=job.pk)
    assert stopped.stop_requested and stopped.status == TrainingJob.Status.STOPPING
    shown = samples(page, 5)
    assert len(set(shown)) == 1, f"the clock ran on after the stop: {shown}"
    assert shown[0] == pytest.approx(stopped.training_seconds, abs=0.1)
