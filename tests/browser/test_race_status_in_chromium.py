"""The live state of an evaluation or a race is said once, by its status, which follows the job
over the websocket: no message beside it that the job has left behind."""

import re

import pytest
from playwright.sync_api import Page, expect

from racing import broadcasts
from racing import services as racing_services
from racing.models import Submission
from tests.browser.conftest import off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from tests.helpers.league import event, race_evaluation
from tests.helpers.models import ready_model
from training import selectors, streams
from training.models import EvaluationJob, EvaluationTrial

pytestmark = pytest.mark.django_db(transaction=True)
QUEUED = re.compile("queued", re.IGNORECASE)


def announce_evaluation(evaluation: EvaluationJob, **fields) -> None:
    """What the worker does as an evaluation moves on: store its state, tell its page."""
    EvaluationJob.objects.filter(pk=evaluation.pk).update(**fields)
    evaluation.refresh_from_db()
    status = selectors.evaluation_status(evaluation=evaluation)
    off_the_loop(streams.announce, streams.evaluation_group(evaluation.pk), status)


def test_the_evaluation_page_says_queued_once_then_follows_the_evaluation(
    page: Page, alice, tracks
):
    model = ready_model(alice)
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/evaluate/")
    page.get_by_role("button", name=re.compile("^(Start|Evaluate)")).click()
    status = page.locator("[data-live-status]")
    # A worker of an earlier test may take the evaluation at once: whatever its state, only the
    # status line says it, and no "The evaluation is queued." message stands beside it.
    expect(status).to_have_text(re.compile("^(Queued|Initializing|In progress|Completed)"))
    expect(page.get_by_text("The evaluation is queued.")).to_have_count(0)

    # An evaluation no worker takes: the page says "Queued" once, then follows it.
    evaluation = EvaluationJob.objects.create(model=model, track=model.track)
    page.goto(f"/models/{model.pk}/evaluations/{evaluation.pk}/")
    expect(status).to_have_text("Queued")
    expect(page.get_by_text(QUEUED)).to_have_count(1)  # the status line, nothing else

    announce_evaluation(evaluation, status=EvaluationJob.Status.IN_PROGRESS, message="Racing")
    expect(status).to_have_text("In progress · Racing")
    expect(page.get_by_text(QUEUED)).to_have_count(0)


def queued_submission(racer) -> Submission:
    """``racer``'s ready model entered in a one-lap race, its evaluation queued."""
    model = ready_model(racer)
    trial = event(laps_required=1, laps_to_drive=1)
    return Submission.objects.create(
        event=trial,
        racer=racer,
        model=model,
        model_name=model.name,
        evaluation=race_evaluation(model, trial),
    )


def test_the_submission_page_follows_its_race_and_then_shows_the_score(page: Page, alice, tracks):
    submission = queued_submission(alice)
    log_in(page, "alice", PASSWORD)
    page.goto(submission.get_absolute_url())
    badge = page.locator("[data-submission-status]")
    expect(badge).to_have_text("Queued")
    expect(page.get_by_text(re.compile("soon", re.IGNORECASE))).to_have_count(0)
    expect(page.locator("[data-submission-live]")).to_have_attribute("data-listening", "true")

    Submission.objects.filter(pk=submission.pk).update(status=Submission.Status.IN_PROGRESS)
    submission.refresh_from_db()
    off_the_loop(broadcasts.announce_submission, submission)
    expect(badge).to_have_text("In progress")
    expect(badge).to_have_class(re.compile("badge-in_progress"))
    expect(page.get_by_text(QUEUED)).to_have_count(0)

    lap = EvaluationTrial(number=1, time_ms=12_345, progress=100, status="lap_complete")
    off_the_loop(racing_services.submission_score, submission=submission, trials=[lap])
    expect(badge).to_have_text("Completed")  # the page reloaded with the result
    expect(page.get_by_text("Qualified")).to_be_visible()
    expect(page.locator("table")).to_contain_text("0:12.345")


# The page's websocket connects only when the test says so: what happens between the page being
# drawn and its socket opening can then be staged.
HELD_SOCKETS = """
const Real = window.WebSocket;
const held = [];
window.WebSocket = class extends EventTarget {
  constructor(url) {
    super();
    held.push(() => {
      const socket = new Real(url);
      for (const type of ["open", "message", "close", "error"]) {
        const relay = (event) => this.dispatchEvent(new event.constructor(type, event));
        socket.addEventListener(type, relay);
      }
    });
  }
};
window.openHeldSockets = () => held.splice(0).forEach((open) => open());
"""


def test_the_submission_page_catches_up_with_a_race_that_moved_on_while_it_opened(
    page: Page, alice, tracks
):
    submission = queued_submission(alice)
    log_in(page, "alice", PASSWORD)
    page.add_init_script(HELD_SOCKETS)
    page.goto(submission.get_absolute_url())
    badge = page.locator("[data-submission-status]")
    expect(badge).to_have_text("Queued")
    # The race starts, and says so to nobody, before the page's socket opens.
    Submission.objects.filter(pk=submission.pk).update(status=Submission.Status.IN_PROGRESS)
    page.evaluate("openHeldSockets()")
    expect(page.locator("[data-submission-live]")).to_have_attribute("data-listening", "true")
    expect(badge).to_have_text("In progress")
