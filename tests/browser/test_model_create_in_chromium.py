import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_accounts_in_chromium import log_in
from tests.conftest import PASSWORD
from training.models import RLModel

pytestmark = pytest.mark.django_db(transaction=True)


def test_a_racer_creates_a_model_with_a_generated_action_space(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/")
    page.get_by_role("link", name="Create model").click()
    page.get_by_label("Name").fill("seven-steering")
    page.locator(".track-choice", has_text="Pitlane Oval").click()
    expect(page.locator("[data-actions] tr")).to_have_count(10)  # DeepRacer's default

    page.get_by_label("Steering angles").select_option("7")
    page.get_by_label("Speeds").select_option("1")
    page.get_by_label("Maximum speed [m/s]").fill("1.5")
    page.get_by_role("button", name="Generate the table").click()
    expect(page.locator("[data-actions] tr")).to_have_count(7)
    page.get_by_role("button", name="Remove").first.click()
    expect(page.locator("[data-actions] tr")).to_have_count(6)

    # SAC settings show only for SAC; a discrete action space goes with PPO.
    expect(page.get_by_label("SAC alpha (entropy)")).to_be_hidden()
    page.get_by_role("button", name="Create model and start training").click()

    expect(page.get_by_role("heading", name="seven-steering")).to_be_visible()
    expect(page.get_by_text("seven-steering is created; its training is queued.")).to_be_visible()
    model = RLModel.objects.get(name="seven-steering")
    assert model.track.name == "pitlane-oval"
    steering = [a["steering_angle"] for a in model.action_space]
    assert steering == [-20.0, -10.0, 0.0, 10.0, 20.0, 30.0]
    assert {a["speed"] for a in model.action_space} == {1.5}
