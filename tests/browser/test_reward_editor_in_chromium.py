import pytest
from playwright.sync_api import Page, expect

from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in

pytestmark = pytest.mark.django_db(transaction=True)

BROKEN = """import os

def reward_function(params):
    return 1.0
"""


def test_a_racer_validates_a_reward_function_fixes_it_and_sees_its_rewards(
    page: Page, alice, tracks
):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/")
    page.get_by_role("link", name="Write a reward function").click()
    editor = page.locator(".CodeMirror")
    expect(editor).to_be_visible()
    expect(page.locator(".CodeMirror-linenumber").first).to_be_visible()

    # An import that is not allowed: the error names the line, which gets a marker.
    editor.evaluate("(element, code) => element.CodeMirror.setValue(code)", BROKEN)
    page.get_by_role("button", name="Validate").click()
    expect(page.locator("[data-errors] p")).to_have_text(
        "import (line 1): Only math, random, numpy, scipy and shapely may be imported, not os."
    )
    expect(page.locator(".reward-error-marker")).to_have_count(1)
    expect(page.locator(".reward-error-line")).to_have_count(1)

    # An example replaces the code (after asking), and validates on the chosen track.
    page.once("dialog", lambda dialog: dialog.accept())
    page.get_by_role("button", name="Use this example").nth(2).click()
    expect(editor).to_contain_text("ABS_STEERING_THRESHOLD")
    page.get_by_label("Try it on").select_option("hairpin-alley")
    page.get_by_role("button", name="Validate").click()
    validated = {"timeout": 30_000}  # the sandbox runs five samples: seconds on a busy machine
    expect(page.locator("[data-status]")).to_have_text("Valid: ready to train.", **validated)
    rows = page.locator("[data-samples] tr")
    expect(rows).to_have_count(5)
    expect(rows.nth(2)).to_contain_text("off-track")
    expect(rows.nth(2).locator("td").nth(2)).to_have_text("0.00100000")
    expect(page.locator(".reward-error-marker")).to_have_count(0)
