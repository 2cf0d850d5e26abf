"""The league as a visitor finds it, in Chromium: a leaderboard offers to sign up (not to manage
the race), and its "Watch" opens the run's page, which fits a phone."""

import re

import cv2
import numpy as np
import pytest
from django.core.files.base import ContentFile
from django.core.files.storage import default_storage
from playwright.sync_api import Page, expect

from racing.models import Submission
from tests.browser.checks import page_problems
from tests.browser.conftest import off_the_loop
from tests.helpers.browser import sign_up_here
from tests.helpers.league import event, scored

pytestmark = pytest.mark.django_db(transaction=True)


def a_second_of_video(submission: Submission, tmp_path) -> None:
    """A race's video as the evaluation records it (VP8, 640x480), one second long."""
    path = tmp_path / "video.webm"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"VP80"), 15, (640, 480))
    for shade in range(15):
        writer.write(np.full((480, 640, 3), shade * 10, dtype=np.uint8))
    writer.release()
    name = f"league/submissions/{submission.pk}/video.webm"
    stored = default_storage.save(name, ContentFile(path.read_bytes()))
    Submission.objects.filter(pk=submission.pk).update(video=stored)


def test_a_visitor_is_offered_to_sign_up_and_comes_back_to_the_leaderboard(page: Page, tracks):
    trial = event()
    page.goto(trial.get_absolute_url())
    expect(page.get_by_role("link", name="Manage this race")).to_have_count(0)
    page.get_by_role("link", name="Sign up to race").click()
    sign_up_here(page, "dana")

    expect(page).to_have_url(re.compile(f"{trial.get_absolute_url()}$"))
    expect(page.get_by_role("link", name="Submit a model")).to_be_visible()
    expect(page.get_by_role("link", name="Sign up to race")).to_have_count(0)
    expect(page.get_by_role("link", name="Manage this race")).to_have_count(0)


def test_watch_opens_the_runs_page_and_it_fits_a_phone(page: Page, alice, tracks, tmp_path):
    trial = event()
    run = off_the_loop(scored, trial, alice, 9_000, 9_500, 10_000, model_name="zoom")
    a_second_of_video(run, tmp_path)
    page.set_viewport_size({"width": 390, "height": 844})
    page.goto(trial.get_absolute_url())
    page.get_by_role("link", name="Watch").click()

    expect(page).to_have_url(re.compile(f"/races/submissions/{run.pk}/#video$"))
    expect(page.get_by_role("heading", name="zoom in Time trial")).to_be_visible()
    expect(page.locator("[data-racer] .racer-name")).to_have_text("alice")
    expect(page.locator("[data-score]")).to_have_text("0:09.500")
    expect(page.locator("[data-place]")).to_have_text("1")
    expect(page.locator("[data-event-rules]")).to_contain_text(
        "Ranked by average of the first 3 consecutive laps"
    )
    expect(page.locator("table tbody tr")).to_have_count(3)
    expect(page.locator("table tbody tr").first).to_contain_text("0:09.000")
    video = page.locator("[data-race-video]")
    page.wait_for_function(
        "() => document.querySelector('[data-race-video]').readyState >= 1", timeout=15_000
    )
    assert video.evaluate("v => [v.videoWidth, v.error]") == [640, None]
    assert video.evaluate("v => v.getBoundingClientRect().right") <= 390
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    assert page_problems(page) == []
