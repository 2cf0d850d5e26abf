"""The help page in Chromium: reached from the navigation, its contents jump to each section."""

from __future__ import annotations

import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import ARTIFACTS

pytestmark = pytest.mark.django_db(transaction=True)


def test_a_visitor_opens_help_from_the_navigation_and_jumps_to_a_section(page: Page):
    page.goto("/")
    page.get_by_role("navigation", name="Main").get_by_role("link", name="Help").click()
    assert page.url.endswith("/help/")
    expect(page.get_by_role("heading", level=1)).to_contain_text("Help")
    page.get_by_role("navigation", name="On this page").get_by_role(
        "link", name="Your model on the car"
    ).click()
    section = page.locator("#physical-car")
    expect(section).to_be_in_viewport()
    expect(section.get_by_text("physicalmodel-", exact=False).first).to_be_visible()
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    page.set_viewport_size({"width": 390, "height": 844})
    page.goto("/help/#hyperparameters")
    expect(page.locator("#clipped-ppo-discount-factor")).to_contain_text("Raise it:")
    page.screenshot(path=ARTIFACTS / "help-on-a-phone.png", full_page=True)
