"""Every page, at a laptop's 1280 x 800 and a phone's 390 x 844: readable contrast and nothing
wider than the screen; forms that work from the keyboard alone and keep what was typed when
they report an error; dates in the racer's own time zone."""

from __future__ import annotations

from datetime import datetime
from zoneinfo import ZoneInfo

import pytest
from playwright.sync_api import Page, expect

from racing.models import Season
from racing.services import demo_season_load
from simulator.trace import to_csv
from tests.browser.checks import page_problems
from tests.browser.conftest import ARTIFACTS, off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.analysis import HAND_WRITTEN
from tests.helpers.browser import log_in
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from training import artifacts
from training.models import Vehicle

pytestmark = pytest.mark.django_db(transaction=True)

SCREENS = {"laptop": {"width": 1280, "height": 800}, "phone": {"width": 390, "height": 844}}
PUBLIC = [
    "/",
    "/accounts/login/",
    "/accounts/signup/",
    "/races/",
    "/leaderboards/",
    "/help/",
    "/nothing/",
]


def racer_pages(alice) -> list[str]:
    model = ready_model(alice)
    trial = event("Time trial")
    submission = off_the_loop(scored, trial, alice, 10_000, 11_000, 12_000, model_name=model.name)
    season = Season.objects.get(name="Test season")
    vehicle = Vehicle.objects.create(owner=alice, name="page-car", shell_colour="#f5f5f5")
    artifacts.save(model, artifacts.training_trace(1), to_csv(HAND_WRITTEN))  # for its Analysis
    return [
        "/models/",
        f"/models/{model.pk}/",
        f"/models/{model.pk}/evaluate/",
        f"/models/{model.pk}/delete/",
        "/models/create/",
        f"/models/create/?clone={model.pk}",
        "/models/import/",
        "/models/reward-function/",
        "/tracks/reInvent2019_track/",
        "/garage/",
        f"/garage/{vehicle.pk}/edit/",
        f"/garage/{vehicle.pk}/delete/",
        "/races/",
        "/races/submit/",
        "/races/submissions/",
        submission.get_absolute_url(),
        "/leaderboards/",
        trial.get_absolute_url(),
        f"/seasons/{season.pk}/",
        "/races/community/new/",
        "/notifications/",
        "/accounts/password/",
        f"/models/{model.pk}/analysis/",
        f"/events/{trial.slug}/live/",
        f"/events/{trial.slug}/broadcast/",
    ]


def test_every_page_reads_well_on_a_laptop_and_a_phone(page: Page, alice, tracks):
    demo_season_load()
    pages = racer_pages(alice)
    problems = []
    for screen, size in SCREENS.items():
        page.set_viewport_size(size)
        folder = ARTIFACTS.parent / screen
        folder.mkdir(parents=True, exist_ok=True)
        for old in folder.glob("*.png"):
            old.unlink()
        page.context.clear_cookies()
        for path in PUBLIC:
            page.goto(path)
            problems += page_problems(page)
        log_in(page, "alice", PASSWORD)
        for number, path in enumerate(pages, start=1):
            page.goto(path)
            problems += page_problems(page)
            name = path.strip("/").replace("/", "-").replace("?", "-").replace("=", "-")
            page.screenshot(path=folder / f"{number:02d}-{name or 'home'}.png", full_page=True)
    (ARTIFACTS.parent / "page-problems.txt").write_text("".join(f"{p}\n" for p in problems))
    assert problems == []


def test_a_racer_logs_in_and_builds_a_vehicle_with_the_keyboard_alone(page: Page, alice):
    page.goto("/accounts/login/")

    def tab_to(name: str) -> None:
        for _ in range(30):
            page.keyboard.press("Tab")
            if page.evaluate("() => document.activeElement.name") == name:
                focused = "() => getComputedStyle(document.activeElement).outlineStyle"
                assert page.evaluate(focused) != "none", f"{name} shows no focus"
                return
        raise AssertionError(f"Tab never reached {name}")

    tab_to("username")
    page.keyboard.type("alice")
    tab_to("password")
    page.keyboard.type(PASSWORD)
    page.keyboard.press("Enter")
    expect(page.get_by_role("heading", name="Welcome back, alice")).to_be_visible()

    page.goto("/garage/")
    tab_to("name")
    page.keyboard.type("keyboard-car")
    tab_to("shell_colour")
    page.keyboard.press("ArrowRight")  # from Black to White
    page.keyboard.press("ArrowRight")  # to Red
    tab_to("camera")
    page.keyboard.press("ArrowDown")  # stereo cameras
    page.keyboard.press("Enter")
    expect(page.get_by_text("keyboard-car is in your garage.")).to_be_visible()
    vehicle = Vehicle.objects.get(owner=alice, name="keyboard-car")
    assert (vehicle.get_shell_colour_display(), vehicle.camera) == ("Red", "STEREO_CAMERAS")


CUSTOM = """def reward_function(params):
    return 1.0 if params["all_wheels_on_track"] else 1e-3
"""


def test_a_model_form_with_a_mistake_keeps_everything_the_racer_chose(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/create/")
    page.get_by_label("Name").fill("keep-it-all")
    page.get_by_label("Description").fill("Everything I typed")
    page.locator(".track-choice:has(input[value=speedway])").click()  # ours, not Ace Speedway
    page.get_by_label("Direction").select_option("clockwise")
    page.get_by_label("Steering angles").select_option("7")
    page.get_by_label("Speeds").select_option("1")
    page.get_by_role("button", name="Generate the table").click()
    page.get_by_label("SAC", exact=True).check()
    page.get_by_label("Continuous", exact=True).check()
    page.get_by_label("Maximum training time [min]").fill("5")
    page.locator(".CodeMirror").evaluate("(e, code) => e.CodeMirror.setValue(code)", CUSTOM)
    page.get_by_role("button", name="Create model and start training").click()

    expect(page.get_by_text("The model was not created: fix what is marked below.")).to_be_visible()
    expect(page.get_by_text("The maximum training time is 10 to 1440 minutes.")).to_be_visible()
    expect(page.get_by_label("Name")).to_have_value("keep-it-all")
    expect(page.get_by_label("Description")).to_have_value("Everything I typed")
    expect(page.locator(".track-choice input[value=speedway]")).to_be_checked()
    expect(page.get_by_label("Direction")).to_have_value("clockwise")
    expect(page.get_by_label("SAC", exact=True)).to_be_checked()
    expect(page.get_by_label("Continuous", exact=True)).to_be_checked()
    expect(page.get_by_label("Maximum training time [min]")).to_have_value("5")
    code = page.locator(".CodeMirror").evaluate("e => e.CodeMirror.getValue()")
    assert code.strip() == CUSTOM.strip()
    page.get_by_label("Discrete", exact=True).check()
    expect(page.locator("[data-actions] tr")).to_have_count(7)  # the generated table, kept


@pytest.fixture
def tokyo_page(browser, daphne_server) -> Page:
    context = browser.new_context(base_url=daphne_server, timezone_id="Asia/Tokyo")
    yield context.new_page()
    context.close()


def test_dates_are_shown_in_the_racers_own_time_zone(tokyo_page: Page, alice, tracks):
    trial = event("Time trial")
    moment = datetime(2026, 3, 1, 23, 30, tzinfo=ZoneInfo("UTC"))  # 2 March, 08:30 in Tokyo
    off_the_loop(scored, trial, alice, 10_000, 10_000, 10_000, at=moment)
    # The first page a browser sees is relabelled in place; every page after it is written in
    # the zone the browser named.
    for _visit in ("first", "second"):
        tokyo_page.goto(trial.get_absolute_url())
        expect(tokyo_page.locator("td time")).to_have_text("2 Mar 2026, 08:30")
        expect(tokyo_page.locator("[data-time-zone]")).to_have_text("Asia/Tokyo")
    cookies = {cookie["name"]: cookie["value"] for cookie in tokyo_page.context.cookies()}
    assert cookies["pitlane_tz"] == "Asia/Tokyo"
