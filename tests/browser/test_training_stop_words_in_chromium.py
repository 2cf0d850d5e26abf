"""Stopping a training in Chromium (issue 54): the "Stopping: ..." message is seen while the job
stops, and goes when the job has ended under the racer's eyes, as the time split's word of an
evaluation still to come does."""

from __future__ import annotations

import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from tests.helpers.training import training_job
from training import streams
from training.models import Iteration, RLModel, TrainingJob

pytestmark = pytest.mark.django_db(transaction=True)


@pytest.mark.slow
def test_the_stopping_message_goes_when_the_training_ends(page: Page, alice, tracks):
    job = training_job(alice, seconds=60, ago=1)
    Iteration.objects.create(
        job=job,
        number=1,
        reward=1.0,
        completion=20.0,
        episodes=5,
        steps=500,
        wall_seconds=10.0,
        time_split={"driving": 6.0, "update": 4.0},
    )
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{job.model_id}/stop/")
    page.get_by_role("button", name="Stop training").click()
    said = page.get_by_text("Stopping: saving the model from iteration 3.")
    expect(said).to_be_visible()
    to_come = page.get_by_text("Its evaluation drives beside the next iteration.")
    expect(to_come).to_be_visible()

    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED, message="")
    RLModel.objects.filter(pk=job.model_id).update(status=RLModel.Status.READY)
    off_the_loop(streams.announce_training, job.pk)
    expect(page.locator("[data-live-status]")).to_have_text("Completed")
    expect(said).to_be_hidden()
    expect(to_come).to_be_hidden()
    expect(page.get_by_text("Training ended before its evaluation finished.")).to_be_visible()
