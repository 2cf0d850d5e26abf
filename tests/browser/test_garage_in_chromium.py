"""The garage in Chromium: shell colours as swatches chosen from the keyboard, a vehicle edited
and deleted."""

from __future__ import annotations

import pytest
from playwright.sync_api import Page, expect

from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from training.models import Vehicle

pytestmark = pytest.mark.django_db(transaction=True)


def _focused(page: Page, script: str):
    return page.evaluate(f"() => {{ const e = document.activeElement; return {script}; }}")


def test_a_swatch_is_a_coloured_circle_chosen_with_the_arrow_keys(page: Page, alice):
    log_in(page, "alice", PASSWORD)
    page.goto("/garage/")
    red = page.get_by_role("radio", name="Red")
    expect(red).to_be_visible()
    box = red.bounding_box()
    assert box["width"] >= 24 and abs(box["width"] - box["height"]) < 1  # a round target
    assert red.evaluate("e => getComputedStyle(e).backgroundColor") == "rgb(209, 36, 47)"
    assert red.evaluate("e => getComputedStyle(e).borderRadius") == "50%"

    page.get_by_label("Name").fill("swatch-car")
    page.get_by_label("Name").press("Tab")
    assert _focused(page, "e.name") == "shell_colour"
    assert _focused(page, "getComputedStyle(e).outlineStyle") == "solid"  # the focus ring
    page.keyboard.press("ArrowRight")  # from Black to White
    page.keyboard.press("ArrowRight")  # to Red
    page.keyboard.press("ArrowRight")  # to Orange
    page.keyboard.press("ArrowLeft")  # back to Red
    expect(red).to_be_checked()
    assert _focused(page, "e.value") == "#d1242f"
    ring = red.evaluate("e => getComputedStyle(e).boxShadow")
    assert ring != "none" and ring != page.get_by_role("radio", name="Blue").evaluate(
        "e => getComputedStyle(e).boxShadow"
    )  # the chosen one is ringed
    page.keyboard.press("Enter")
    expect(page.get_by_text("swatch-car is in your garage.")).to_be_visible()
    assert Vehicle.objects.get(owner=alice, name="swatch-car").get_shell_colour_display() == "Red"


def test_a_racer_repaints_and_then_deletes_a_vehicle(page: Page, alice):
    Vehicle.objects.create(owner=alice, name="Rocket", shell_colour="#1f2328")
    log_in(page, "alice", PASSWORD)
    page.goto("/garage/")
    page.get_by_role("link", name="Edit Rocket").click()
    expect(page.get_by_role("radio", name="Black")).to_be_checked()
    page.get_by_role("radio", name="Purple").click()
    page.get_by_label("Name").fill("Comet")
    page.get_by_role("button", name="Save").click()
    expect(page.get_by_text("Comet is saved.")).to_be_visible()
    expect(page.locator("td", has_text="Purple")).to_be_visible()

    page.get_by_role("link", name="Delete Comet").click()
    expect(page.get_by_role("heading", name="Delete Comet?")).to_be_visible()
    page.get_by_role("button", name="Delete Comet").click()
    expect(page.get_by_text("Comet has left your garage.")).to_be_visible()
    expect(page.get_by_text("Your garage is empty.")).to_be_visible()
