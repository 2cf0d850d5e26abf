import threading

import pytest
from playwright.sync_api import Page, expect

from jobs import evaluation
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from tests.helpers.models import ready_model
from training import services, track_lines

pytestmark = pytest.mark.django_db(transaction=True)


def test_a_racer_reads_the_results_and_plays_the_recorded_video(page: Page, alice, tracks):
    model = ready_model(alice)
    job = services.evaluation_start(
        model=model, settings={"continuous_laps": True, "off_track_penalty": 0}, enqueue=False
    )
    # Playwright's event loop runs in this thread; the evaluator, sync code that sends to the
    # channel layer, runs in a thread of its own, as it does in a worker.
    runner = threading.Thread(target=evaluation.run, args=(job.pk,))
    runner.start()
    runner.join()

    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/")
    page.get_by_role("link", name="Results").click()
    expect(page.locator("[data-live-trials] tbody tr")).to_have_count(3)
    expect(page.locator("[data-live-trials] tbody tr").first).to_contain_text("Lap complete")
    expect(page.locator("[data-live-trials]")).not_to_contain_text("lap_complete")
    expect(page.locator("[data-live-status]")).to_have_text("Completed")
    # Each completed lap against the racing line's: the first from a standing start, the next
    # ones flying (continuous laps), as stored.
    standing, flying = track_lines.line_times(track=job.track, direction=job.direction)
    expect(page.locator("[data-line-times]")).to_contain_text(f"{standing:.2f} s")
    for trial, cell in zip(
        job.trial_rows.order_by("number"), page.locator("[data-against-line]").all(), strict=True
    ):
        line = standing if trial.number == 1 else flying
        driven = (trial.time_ms - trial.penalty_ms) / 1000
        wanted = track_lines.lap_against_line(driven, line) if trial.completed else ""
        expect(cell).to_have_text(wanted)
    assert job.trial_rows.filter(status="lap_complete").exists()

    video = page.locator("[data-evaluation-video]")
    page.wait_for_function(
        "() => document.querySelector('[data-evaluation-video]').readyState >= 2", timeout=15_000
    )
    assert video.evaluate("v => [v.videoWidth, v.videoHeight]") == [640, 480]
    assert video.evaluate("v => v.error") is None
    # Served in byte ranges, the video can be scrubbed: a whole-body 200 leaves seekable [0, 0].
    assert video.evaluate("v => v.seekable.length && v.seekable.end(0)") > 0
    video.evaluate("v => { v.muted = true; return v.play(); }")
    page.wait_for_function(
        "() => document.querySelector('[data-evaluation-video]').currentTime > 0.5"
    )
    expect(page.get_by_role("link", name="Simulation trace (CSV)")).to_be_visible()
    expect(page.get_by_role("link", name="Evaluation metrics (JSON)")).to_be_visible()


def test_a_racer_stops_an_evaluation_from_its_page(page: Page, alice, tracks):
    model = ready_model(alice)
    job = services.evaluation_start(model=model, settings={}, enqueue=False)  # it waits

    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/evaluations/{job.pk}/")
    stop = page.get_by_role("button", name="Stop evaluation")
    expect(stop).to_be_visible()
    stop.click()
    expect(page.locator(".message")).to_have_text("Stopped: the evaluation had not begun.")
    expect(page.locator("[data-live-status]")).to_have_text("Canceled")
    expect(page.get_by_role("button", name="Stop evaluation")).to_have_count(0)
    expect(page.locator("[data-live-failure]")).to_contain_text("Stopped by you before it began.")
    page.goto(f"/models/{model.pk}/")
    expect(page.locator("[data-live-model-status]")).to_have_text("Ready")
