import pytest
from playwright.sync_api import Page, expect

from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in

pytestmark = pytest.mark.django_db(transaction=True)


def test_staff_probe_the_workers_from_the_system_page(page: Page, stella, celery_worker_process):
    """Chromium → Daphne → (enqueued) Celery worker → channel layer → Daphne → Chromium."""
    log_in(page, "stella", PASSWORD)
    page.get_by_role("link", name="System").click()
    expect(page.get_by_text("All up")).to_be_visible()

    button = page.get_by_role("button", name="Probe workers")
    expect(button).to_be_enabled()  # the websocket is open
    button.click()

    log = page.locator("[data-probe-log]")
    expect(log.locator("li[data-ok=true]")).to_have_count(3, timeout=20_000)
    for queue, worker in (("training", "trainer"), ("simulation", "sim"), ("rescoring", "rescore")):
        expect(log.locator(f"li[data-queue={queue}]")).to_contain_text(f"test-{worker}@")
