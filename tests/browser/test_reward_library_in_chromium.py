"""The racer's library of reward functions, in the browser: written and saved on the reward
function page, found in the create form's editor, picked from the create form's "Start from",
and unsaved code that survives Back."""

import pytest
from playwright.sync_api import Page, expect

from tests.browser.checks import page_problems
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from training.models import RewardFunction

pytestmark = pytest.mark.django_db(transaction=True)

MINE = """def reward_function(params):
    # stay on the track, faster is better
    if not params["all_wheels_on_track"]:
        return 1e-3
    return float(params["speed"])
"""

TYPO = """def reward_function(params):
    return float(params["distance_from_centre"])
"""

SET_CODE = "(element, code) => element.CodeMirror.setValue(code)"
GET_CODE = "element => element.CodeMirror.getValue()"
SAVED = {"timeout": 30_000}  # saving validates in the sandbox: seconds on a busy machine
FRAMES = "() => new Promise((done) => requestAnimationFrame(() => requestAnimationFrame(done)))"


def test_a_racer_saves_a_reward_function_and_creates_a_model_with_it(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/")
    page.get_by_role("link", name="Write a reward function").click()
    expect(page.get_by_text("Nothing saved yet.")).to_be_visible()
    editor = page.locator(".CodeMirror")

    # A misspelt key: saving refuses, says so once with the real key, and keeps name and code.
    editor.evaluate(SET_CODE, TYPO)
    page.get_by_label("Name").fill("Speed on track")
    page.get_by_role("button", name="Save", exact=True).click()
    expect(page.get_by_text("It was not saved: the code has 1 error to fix.")).to_be_visible(
        **SAVED
    )
    expect(page.locator("[data-errors] p")).to_have_text(
        "key (line 2): params has no key 'distance_from_centre'; "
        "did you mean 'distance_from_center'?"
    )
    expect(page.locator(".reward-error-marker")).to_have_count(1)
    expect(page.get_by_label("Name")).to_have_value("Speed on track")
    assert editor.evaluate(GET_CODE) == TYPO

    editor.evaluate(SET_CODE, MINE)
    # While a checker runs the code, the page says so, and a second click sends nothing. (The
    # test keeps the first submit on the page, the way a slow answer would.)
    posts = []
    page.on("request", lambda request: request.method == "POST" and posts.append(request.url))
    page.evaluate("window.addEventListener('submit', (e) => e.preventDefault(), {once: true})")
    save = page.get_by_role("button", name="Save", exact=True)
    save.click()
    waiting = page.get_by_role("status").filter(has_text="Checking the code in the sandbox")
    expect(waiting).to_be_visible()
    expect(save).to_have_attribute("aria-disabled", "true")
    page.evaluate("document.querySelector('form[data-busy]').requestSubmit()")
    assert posts == []
    page.evaluate("window.dispatchEvent(new Event('pageshow'))")  # as when the racer comes back
    expect(waiting).to_have_count(0)
    save.click()
    expect(page.get_by_text("Saved “Speed on track”.")).to_be_visible(**SAVED)
    expect(page.get_by_role("heading", name="Reward function: Speed on track")).to_be_visible()
    assert editor.evaluate(GET_CODE) == MINE
    library = page.locator("[data-reward-library]")
    expect(library.get_by_role("link", name="Speed on track", exact=True)).to_be_visible()
    problems = []
    for size in ({"width": 390, "height": 844}, {"width": 1280, "height": 800}):
        page.set_viewport_size(size)
        page.reload()
        expect(page.locator(".CodeMirror-line").first).to_be_visible()
        page.evaluate(FRAMES)  # CodeMirror measures itself once more after the load
        problems += page_problems(page)
    assert problems == []

    # Create a model from the library: the form's editor holds the saved code.
    library.get_by_role("link", name="Create a model with Speed on track").click()
    expect(page.get_by_role("heading", name="Create a model")).to_be_visible()
    assert page.locator(".CodeMirror").evaluate(GET_CODE) == MINE
    expect(page.get_by_label("Start from")).to_have_value(
        f"saved:{RewardFunction.objects.get(owner=alice).pk}"
    )


def test_save_and_create_a_model_takes_new_code_to_the_form_and_back_keeps_it(
    page: Page, alice, tracks
):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/reward-function/")
    page.locator(".CodeMirror").evaluate(SET_CODE, MINE)
    page.get_by_label("Name").fill("fast")
    page.get_by_role("button", name="Save and create a model").click()
    expect(page.get_by_role("heading", name="Create a model")).to_be_visible(**SAVED)
    assert page.locator(".CodeMirror").evaluate(GET_CODE) == MINE

    page.go_back()  # to the reward function page: the racer's saved function, not the default
    expect(page.get_by_role("heading", name="Reward function: fast")).to_be_visible()
    expect(page.locator(".CodeMirror")).to_contain_text("faster is better")
    assert page.locator(".CodeMirror").evaluate(GET_CODE) == MINE
    page.goto("/models/reward-function/")  # a new function starts from the default again
    expect(page.locator(".CodeMirror")).to_contain_text("Follow the centre line")


def test_unsaved_code_on_the_reward_page_survives_leaving_it(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/reward-function/")
    page.locator(".CodeMirror").evaluate(SET_CODE, MINE)
    page.get_by_label("Name").fill("not saved yet")
    page.get_by_role("navigation", name="Main").get_by_role("link", name="Models").click()
    page.go_back()
    expect(page.locator(".CodeMirror")).to_contain_text("faster is better")
    page.goto("/models/")
    page.goto("/models/reward-function/")
    expect(page.get_by_text("What you had not saved is back.")).to_be_visible()
    assert page.locator(".CodeMirror").evaluate(GET_CODE) == MINE
    expect(page.get_by_label("Name")).to_have_value("not saved yet")

    page.get_by_role("button", name="Discard it").click()
    expect(page.locator(".CodeMirror")).to_contain_text("Follow the centre line")
    page.reload()
    expect(page.locator(".CodeMirror")).to_contain_text("Follow the centre line")


def test_the_create_forms_picker_loads_a_saved_function_or_an_example(page: Page, alice, tracks):
    RewardFunction.objects.create(owner=alice, name="Speed on track", source=MINE)
    long_name = "Stay on the track and go as fast as the corners allow, every lap"  # 64
    RewardFunction.objects.create(owner=alice, name=long_name, source=TYPO)
    log_in(page, "alice", PASSWORD)
    page.set_viewport_size({"width": 390, "height": 844})
    page.goto("/models/create/")
    editor = page.locator(".CodeMirror")
    expect(editor).to_contain_text("Follow the centre line")
    page.evaluate(FRAMES)
    assert page_problems(page) == []  # a long name does not widen the page on a phone

    page.get_by_label("Start from").select_option(label="Speed on track")
    page.get_by_role("button", name="Load into the editor").click()
    assert editor.evaluate(GET_CODE) == MINE
    expect(page.locator("[data-status]")).to_have_text("Loaded “Speed on track”.")

    # Code the racer changed is not replaced without asking.
    editor.evaluate(SET_CODE, MINE + "\n# my own change\n")
    page.get_by_label("Start from").select_option(label="Prevent zig-zag")
    page.once("dialog", lambda dialog: dialog.dismiss())
    page.get_by_role("button", name="Load into the editor").click()
    assert "my own change" in editor.evaluate(GET_CODE)
    page.once("dialog", lambda dialog: dialog.accept())
    page.get_by_role("button", name="Load into the editor").click()
    expect(editor).to_contain_text("ABS_STEERING_THRESHOLD")
