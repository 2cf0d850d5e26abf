"""A new racer's whole journey, in Chromium against the real stack: sign up, build a vehicle,
write a reward function, train, watch, stop, evaluate, race, download for the car, clone and
delete. Each page it passes through is kept as a screenshot under test-artifacts/journey/."""

from __future__ import annotations

import io
import json
import re
import tarfile

import pytest
from playwright.sync_api import Page, expect

from racing.models import Submission
from tests.browser.checks import page_problems
from tests.browser.conftest import ARTIFACTS
from tests.helpers.browser import FRAME_BYTES, sign_up
from tests.helpers.league import event
from training.models import RLModel

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.late]

SCREENSHOTS = ARTIFACTS.parent / "journey"
TYPO = """def reward_function(params):
    if params["all_wheels_on_track"]:
        reward = 1.0 - params["distance_from_center"] / params["track_width"]
    else
        reward = 1e-3
    return float(reward)
"""
FIXED = TYPO.replace("    else\n", "    else:\n")


class Album:
    """Numbered full-page screenshots of the pages the journey passes through, each checked for
    contrast and width as it is taken."""

    def __init__(self, page: Page) -> None:
        self.page, self.count, self.problems = page, 0, []
        SCREENSHOTS.mkdir(parents=True, exist_ok=True)
        for old in SCREENSHOTS.glob("*.png"):
            old.unlink()

    def shoot(self, name: str) -> None:
        self.count += 1
        self.problems += page_problems(self.page)
        self.page.screenshot(path=SCREENSHOTS / f"{self.count:02d}-{name}.png", full_page=True)


def test_a_new_racer_goes_from_sign_up_to_the_leaderboard_and_the_car(
    page: Page, tracks, celery_worker_process
):
    # One lap, and no wait at the track's edge: a one-iteration model leaves the track often.
    race = event("Rookie cup", laps_required=1, laps_to_drive=1, off_track_penalty_s=0)
    album = Album(page)

    # Sign up.
    page.goto("/")
    album.shoot("home")
    sign_up(page, "rookie")
    expect(page.get_by_text("Welcome to Pitlane, rookie!")).to_be_visible()
    album.shoot("welcome")

    # A vehicle in the garage.
    page.get_by_role("navigation", name="Main").get_by_role("link", name="Garage").click()
    expect(page.get_by_text("Your garage is empty.")).to_be_visible()
    page.get_by_label("Name").fill("orange-one")
    page.get_by_label("Orange").check()
    page.get_by_role("button", name="Add to garage").click()
    expect(page.get_by_text("orange-one is in your garage.")).to_be_visible()
    album.shoot("garage")

    # A model with a tiny time budget, its reward function fixed in the editor.
    page.get_by_role("navigation", name="Main").get_by_role("link", name="Models").click()
    page.get_by_role("link", name="Create model").click()
    page.get_by_label("Name").fill("first-laps")
    page.locator(".track-choice", has_text="Pitlane Oval").click()
    page.get_by_label("Vehicle").select_option(label="orange-one")
    # DeepRacer's action space, twice as fast: its laps, and so the evaluation and the race that
    # record them, take half the time.
    page.get_by_label("Maximum speed [m/s]").fill("2")
    page.get_by_role("button", name="Generate the table").click()
    page.locator("[data-when-algorithm=clipped_ppo]").get_by_label(
        "Episodes between policy updates"
    ).fill("5")
    page.get_by_label("Maximum training time [min]").fill("10")
    editor = page.locator(".CodeMirror")
    editor.evaluate("(element, code) => element.CodeMirror.setValue(code)", TYPO)
    page.get_by_role("button", name="Validate").click()
    expect(page.locator("[data-errors] p")).to_contain_text("line 4")
    expect(page.locator(".reward-error-line")).to_have_count(1)
    album.shoot("reward-error")
    editor.evaluate("(element, code) => element.CodeMirror.setValue(code)", FIXED)
    page.get_by_role("button", name="Validate").click()
    expect(page.locator("[data-status]")).to_have_text("Valid: ready to train.")
    expect(page.locator(".reward-error-line")).to_have_count(0)
    album.shoot("model-create")
    page.get_by_role("button", name="Create model and start training").click()
    expect(page.get_by_role("heading", name="first-laps")).to_be_visible()
    model = RLModel.objects.get(name="first-laps")
    assert model.vehicle.name == "orange-one" and model.max_minutes == 10
    assert {action["speed"] for action in model.action_space} == {1.0, 2.0}

    # Training: frames arrive and change; the graph gets its points.
    section = page.locator("[data-live-url]")
    frame = page.locator("[data-live-frame]")
    expect(frame).to_be_visible(timeout=90_000)
    first = frame.evaluate(FRAME_BYTES)
    page.wait_for_function(
        "seq => Number(document.querySelector('[data-live-frame]').dataset.seq) > seq + 5",
        arg=int(frame.get_attribute("data-seq")),
    )
    assert frame.evaluate(FRAME_BYTES) != first
    expect(page.locator("[data-live-time]")).to_contain_text("left")
    chart = page.locator("[data-live-chart]")
    page.wait_for_function(  # one iteration or more: several cars a worker may learn fast
        "() => Number(document.querySelector('[data-live-chart]').dataset.iterations) >= 1",
        timeout=120_000,
    )
    assert int(chart.get_attribute("data-points")) > 0
    album.shoot("training")

    page.get_by_role("button", name="Stop training").click()
    stop = page.get_by_role("dialog")
    expect(stop).to_contain_text("billed for the time used up to the stop")
    stop.get_by_role("button", name="Stop training").click()
    expect(section).to_have_attribute("data-job-status", "COMPLETED", timeout=60_000)
    expect(page.locator("[data-live-model-status]")).to_have_text("Ready")

    # Evaluate: the results table fills and the recorded video plays.
    page.get_by_role("link", name="Evaluate").click()
    page.get_by_label("Off-track penalty [s]").fill("0")
    # A model of one iteration may circle its way round for minutes: its trials end where it
    # first leaves the track, so their number, not the car's luck, bounds how long it drives.
    page.get_by_label("Resets allowed").fill("0")
    album.shoot("evaluate")
    page.get_by_role("button", name="Start the evaluation").click()
    trials = page.locator("[data-live-trials] tbody tr")
    expect(trials).to_have_count(3, timeout=180_000)
    video = page.locator("[data-evaluation-video]")
    page.wait_for_function(
        "() => document.querySelector('[data-evaluation-video]')?.readyState >= 2",
        timeout=60_000,
    )
    video.evaluate("v => { v.muted = true; return v.play(); }")
    page.wait_for_function(
        "() => document.querySelector('[data-evaluation-video]').currentTime > 0.5"
    )
    album.shoot("evaluation")

    # Race: submit to the open event; the run shows on its leaderboard with its laps.
    page.get_by_role("link", name="first-laps").first.click()
    page.get_by_role("link", name="Submit to a race").click()
    events = page.get_by_label("Event")
    events.select_option(events.locator("option", has_text="Rookie cup").get_attribute("value"))
    album.shoot("submit")
    page.get_by_role("button", name="Submit").click()
    expect(page.locator("[data-submission-status]")).to_have_text(
        re.compile("Completed|Failed"), timeout=180_000
    )
    submission = Submission.objects.get(event=race)
    assert submission.status == Submission.Status.COMPLETED
    # the page reloads itself with the laps once the race has ended: shoot that page, not the
    # one it leaves (a shot taken as it navigates loses its script: a flake of the full suite)
    expect(page.locator("tr[data-lap='1']")).to_be_visible()
    page.wait_for_load_state()
    album.shoot("submission")
    page.get_by_role("link", name="Leaderboard", exact=True).click()
    mine = page.locator("[data-my-submissions]")
    expect(mine).to_contain_text("first-laps")
    expect(mine).to_contain_text(f"{submission.laps_completed} of 1")
    album.shoot("leaderboard")

    # The archive for the physical car.
    page.goto(f"/models/{model.pk}/")
    with page.expect_download() as download:
        page.get_by_role("button", name="physicalmodel-first-laps.tar.gz").click()
    assert download.value.suggested_filename == "physicalmodel-first-laps.tar.gz"
    with tarfile.open(fileobj=io.BytesIO(open(download.value.path(), "rb").read())) as archive:
        names = sorted(archive.getnames())
        metadata = json.load(archive.extractfile("model_metadata.json"))
    assert names == ["agent/model.pb", "model_metadata.json"]
    assert metadata["action_space"] == model.action_space

    # Clone, then delete the clone.
    page.get_by_role("link", name="Clone").click()
    expect(page.get_by_role("heading", name="Clone first-laps")).to_be_visible()
    page.get_by_label("Name").fill("first-laps-clone")
    page.get_by_role("button", name="Create model and start training").click()
    expect(page.get_by_role("heading", name="first-laps-clone")).to_be_visible()
    album.shoot("clone")
    page.get_by_role("button", name="Stop training").click()  # a training model is not deleted
    page.get_by_role("dialog").get_by_role("button", name="Stop training").click()
    expect(page.locator("[data-live-model-status]")).to_have_text("Ready", timeout=60_000)
    page.get_by_role("link", name="Delete").click()
    page.get_by_role("button", name="Delete first-laps-clone").click()
    expect(page.get_by_text("Deleted first-laps-clone and all its files.")).to_be_visible()
    album.shoot("models")
    assert list(RLModel.objects.values_list("name", flat=True)) == ["first-laps"]
    assert album.problems == []
