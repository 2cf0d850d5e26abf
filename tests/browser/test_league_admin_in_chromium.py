"""League staff in the admin, in Chromium: a season's inline event table and the events list fit
a laptop screen, and a new event's slug fills in from its name."""

import pytest
from django.contrib.auth.models import User
from playwright.sync_api import Page, expect

from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import expect_seen, log_in
from tests.helpers.league import event

pytestmark = pytest.mark.django_db(transaction=True)


@pytest.fixture
def race_staff(db) -> User:
    """Staff who may change seasons (the "Race staff" group's rows do not outlive the flush
    between browser tests, so a superuser stands in)."""
    return User.objects.create_superuser("rita", password=PASSWORD)


def test_the_seasons_event_table_fits_a_laptop_and_fills_slugs(page: Page, race_staff, tracks):
    page.set_viewport_size({"width": 1280, "height": 800})
    log_in(page, "rita", PASSWORD)
    page.goto("/admin/racing/season/add/")
    page.get_by_text("Add another Event").click()
    table = page.locator(".inline-group table")
    expect(table).to_be_visible()
    wider = table.evaluate(
        "t => t.getBoundingClientRect().right - document.documentElement.clientWidth"
    )
    assert wider <= 0, f"the event table runs {wider} px past the window"
    clipped = page.locator(".inline-group").evaluate(
        "g => [...g.querySelectorAll('*')].some(e => e.scrollWidth > e.clientWidth + 1"
        " && getComputedStyle(e).overflowX !== 'visible')"
    )
    assert not clipped, "the event table scrolls sideways inside the page"

    page.locator("#id_events-0-name").press_sequentially("Summer Cup July")
    expect(page.locator("#id_events-0-slug")).to_have_value("summer-cup-july")


def test_the_events_list_shows_every_kind_of_race_within_a_laptop_screen(
    page: Page, race_staff, tracks
):
    event("Club Pro Duel", division="PRO", cars=2)
    event("Track day", physical=True, any_division=True)
    page.set_viewport_size({"width": 1366, "height": 850})
    log_in(page, "rita", PASSWORD)
    page.goto("/admin/racing/event/")
    duel = page.locator("tr", has_text="Club Pro Duel")
    expect(duel).to_contain_text("Time trial, 2 cars a race")
    expect(page.locator("tr", has_text="Track day")).to_contain_text("Time trial, real cars")
    expect(page.locator("tr", has_text="Track day")).to_contain_text("Open and Pro")
    expect_seen(duel.locator("td").last)  # the last column, in the window
    wider = page.evaluate("document.documentElement.scrollWidth - innerWidth")
    assert wider <= 0, f"the events list runs {wider} px past the window"
