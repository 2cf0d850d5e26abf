"""Layout the racer sees, at a laptop's 1280 x 800 and a phone's 390 x 844: videos that fit the
screen, the Analysis tab's figures holding their captions, the live video's waiting notice clear
of the frame's status bar, and a log that reads oldest first and follows the newest line."""

from __future__ import annotations

import pytest
from playwright.sync_api import Page, expect

from racing.models import Submission
from simulator.trace import to_csv
from tests.browser.checks import page_problems
from tests.browser.conftest import off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.analysis import HAND_WRITTEN
from tests.helpers.browser import log_in
from tests.helpers.league import event, race_evaluation, scored
from tests.helpers.models import ready_model
from training import artifacts
from training.models import EvaluationJob, JobLogLine, TrainingJob

pytestmark = pytest.mark.django_db(transaction=True)

LAPTOP = {"width": 1280, "height": 800}
PHONE = {"width": 390, "height": 844}


def test_every_video_fits_a_phones_screen(page: Page, alice, tracks):
    model = ready_model(alice)
    trial = event("Time trial")
    submission = off_the_loop(scored, trial, alice, 10_000, 11_000, 12_000, model_name=model.name)
    Submission.objects.filter(pk=submission.pk).update(video="races/video.webm")
    evaluation = race_evaluation(model, trial)
    EvaluationJob.objects.filter(pk=evaluation.pk).update(
        status=EvaluationJob.Status.COMPLETED, video="evaluations/video.webm"
    )
    log_in(page, "alice", PASSWORD)
    page.set_viewport_size(PHONE)
    problems = []
    for path in (submission.get_absolute_url(), f"/models/{model.pk}/evaluations/{evaluation.pk}/"):
        page.goto(path)
        expect(page.locator("video")).to_have_count(1)
        problems += page_problems(page)
    assert problems == []


# Each figure's caption and links, against the figure's box and the next heading's.
FIGURES = """() => [...document.querySelectorAll("figure.analysis-chart, figure.track-map")]
  .filter((figure) => figure.offsetParent !== null)
  .map((figure) => {
    const box = figure.getBoundingClientRect();
    const inside = [...figure.querySelectorAll("figcaption, figcaption a")].map((element) => {
      const part = element.getBoundingClientRect();
      return part.top >= box.top - 0.5 && part.bottom <= box.bottom + 0.5;
    });
    const headings = [...document.querySelectorAll("h2, h3")].filter((heading) =>
      heading.offsetParent !== null
      && (figure.compareDocumentPosition(heading) & Node.DOCUMENT_POSITION_FOLLOWING));
    const caption = figure.querySelector("figcaption").getBoundingClientRect();
    const next = headings.length ? headings[0].getBoundingClientRect().top : Infinity;
    const name = [...figure.querySelector("canvas").attributes].map((a) => a.name)[0];
    return { figure: name, inside: inside.every(Boolean), clear: caption.bottom <= next };
  })"""


def test_the_analysis_figures_hold_their_captions_and_links(page: Page, alice, tracks):
    model = ready_model(alice)
    artifacts.save(model, artifacts.training_trace(1), to_csv(HAND_WRITTEN))
    log_in(page, "alice", PASSWORD)
    for size in (LAPTOP, PHONE):
        page.set_viewport_size(size)
        page.goto(f"/models/{model.pk}/analysis/")
        expect(page.locator("[data-analysis]")).to_have_attribute("data-loaded", "1")
        figures = page.evaluate(FIGURES)
        assert len(figures) == 4, figures
        wrong = [f for f in figures if not (f["inside"] and f["clear"])]
        assert wrong == [], (size, wrong)


# The frame's status bar: its bottom 30 of 480 px (simulator/spectator.py, _draw_status).
STATUS_BAR = """() => {
  const frame = document.querySelector("[data-live-frame]").getBoundingClientRect();
  const notice = document.querySelector("[data-live-overlay]").getBoundingClientRect();
  const bar = frame.bottom - frame.height * 30 / 480;
  return { noticeBottom: notice.bottom, barTop: bar, noticeHeight: notice.height,
           within: notice.top >= frame.top && notice.right <= frame.right };
}"""
A_FRAME = """() => {
  const canvas = Object.assign(document.createElement("canvas"), { width: 640, height: 480 });
  const frame = document.querySelector("[data-live-frame]");
  frame.src = canvas.toDataURL("image/png");
  frame.hidden = false;
  frame.dataset.view = "spectator";
  const notice = document.querySelector("[data-live-overlay]");
  notice.textContent = "The car waits while the policy is updated.";
  notice.hidden = false;
}"""


def test_the_cars_waiting_notice_leaves_the_frames_status_bar_in_sight(page: Page, alice, tracks):
    model = ready_model(alice)
    TrainingJob.objects.create(model=model, status=TrainingJob.Status.QUEUED)  # a live video
    log_in(page, "alice", PASSWORD)
    for size in (LAPTOP, PHONE):
        page.set_viewport_size(size)
        page.goto(f"/models/{model.pk}/")
        expect(page.locator("[data-live-overlay]")).to_be_visible()
        page.evaluate(A_FRAME)
        expect(page.locator("[data-live-frame]")).to_be_visible()
        boxes = page.evaluate(STATUS_BAR)
        assert boxes["noticeHeight"] > 0 and boxes["within"], boxes
        assert boxes["noticeBottom"] <= boxes["barTop"], (size, boxes)


AT_BOTTOM = "log => log.scrollHeight - log.scrollTop - log.clientHeight <= 8"


def test_the_log_reads_oldest_first_and_follows_the_newest_line(page: Page, alice, tracks):
    model = ready_model(alice)
    job = model.jobs.get()
    JobLogLine.objects.bulk_create(JobLogLine(job=job, text=f"line {n}") for n in range(60))
    log_in(page, "alice", PASSWORD)
    page.set_viewport_size(PHONE)
    page.goto(f"/models/{model.pk}/")
    log = page.locator("[data-log]")
    lines = log.locator("li")
    expect(lines).to_have_count(60)
    expect(lines.first).to_contain_text("line 0")  # time order, as the download
    expect(lines.last).to_contain_text("line 59")
    jump = page.get_by_role("button", name="Jump to newest")
    assert log.evaluate(AT_BOTTOM)  # it opens on the newest lines
    expect(jump).to_be_hidden()

    # Scrolled up to read, the racer stays there and is offered the way back.
    log.evaluate("log => { log.scrollTop = 0; }")
    expect(jump).to_be_visible()
    jump.click()
    page.wait_for_function(f"() => ({AT_BOTTOM})(document.querySelector('[data-log]'))")
    expect(jump).to_be_hidden()

    # At the bottom, new lines are followed when the job says something new.
    JobLogLine.objects.create(job=job, text="line 60")
    page.evaluate("() => document.dispatchEvent(new CustomEvent('pitlane:job-update'))")
    expect(lines.last).to_contain_text("line 60", timeout=15_000)
    page.wait_for_function(f"() => ({AT_BOTTOM})(document.querySelector('[data-log]'))")
    expect(jump).to_be_hidden()
