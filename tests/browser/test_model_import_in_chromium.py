"""The import page in the browser: a taken name is said as it is typed, before any upload, and
the form is not sent while it is; after an attempt the server refuses, the chosen archive is
kept, so correcting the name is enough. An import says what it creates: a car archive's model
has no training history on its page; a folder without weights is previewed, its track changed,
then confirmed. Then the bell: a notification shows as a count in the navigation, and its page
marks them read."""

import io

import pytest
from playwright.sync_api import Page, expect

from archives import imports
from notifications import services as notifications
from tests.browser.checks import page_problems
from tests.browser.conftest import off_the_loop
from tests.helpers.accounts import PASSWORD
from tests.helpers.archives import (
    car_archive,
    deepracer_folder,
    trained_with_history,
    virtual_archive,
)
from tests.helpers.browser import log_in
from tests.helpers.models import ready_model
from training import services
from training.models import RLModel

pytestmark = pytest.mark.django_db(transaction=True)


def test_the_import_page_checks_the_name_early_and_keeps_the_chosen_archive(
    page: Page, alice, tracks, tmp_path
):
    archive = tmp_path / "virtualmodel-straight-ahead.tar.gz"
    archive.write_bytes(virtual_archive(trained_with_history(alice)))
    page.set_default_timeout(60_000)  # an upload of megabytes on a busy machine
    log_in(page, "alice", PASSWORD)
    page.goto("/models/import/")
    name = page.get_by_label("Name", exact=True)
    status = page.locator("[data-name-status]")

    # As the racer types a name they already use, the page says so; the form is not sent.
    name.fill("Straight-Ahead")
    expect(status).to_have_text(
        "You already have a model named “Straight-Ahead”; choose another name."
    )
    page.get_by_label("Archive (.tar.gz)").set_input_files(archive)
    page.get_by_role("button", name="Import").click()
    expect(name).to_be_focused()
    expect(page.locator("[data-kept-archive]")).to_have_count(0)  # nothing was uploaded
    name.fill("fresh-name")
    expect(status).to_have_text("")

    # Left empty, the name is the archive's, which is taken: the server says so after the
    # upload, and keeps the archive.
    name.fill("")
    page.get_by_role("button", name="Import").click()
    expect(page.locator("[data-kept-archive]")).to_have_text(
        "Using virtualmodel-straight-ahead.tar.gz you uploaded; choose another file to replace it."
    )
    expect(status).to_contain_text("You already have a model named “straight-ahead”")
    assert page_problems(page) == []
    name.fill("imported-again")
    page.get_by_role("button", name="Import").click()
    expect(page.get_by_role("heading", name="imported-again")).to_be_visible()
    expect(page.locator("[data-live-progress]")).to_have_text("2 iterations, 6 episodes, 210 steps")
    assert RLModel.objects.get(owner=alice, name="imported-again").jobs.get().iterations == 2
    # The archive (from before Pitlane carried its exact figures and traces) says, on the
    # model's page for as long as it lives, what the import rebuilt and what is missing.
    notes = page.locator("[data-import-notes]")
    expect(notes).to_contain_text("Training figures rebuilt from DeepRacer's metrics")
    expect(notes).to_contain_text("no simulation traces (training-simtrace)")
    page.reload()  # not a message that goes once read
    expect(notes).to_be_visible()
    assert page_problems(page) == []


def test_an_import_says_what_it_creates_and_asks_before_it_trains(
    page: Page, alice, tracks, tmp_path
):
    # A car archive: a driving model without training history, said so on its page.
    car = imports.import_model(
        owner=alice, archive=io.BytesIO(car_archive(alice)), name="from-the-car"
    ).model
    errors = []
    page.on("pageerror", lambda error: errors.append(str(error)))
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{car.pk}/")
    expect(page.locator("[data-imported-training]")).to_contain_text(
        "A driving model without training history."
    )
    expect(page.locator("[data-live-time]")).to_have_count(0)  # no training clock
    expect(page.get_by_text("The first policy update comes after")).to_have_count(0)
    expect(page.locator("[data-no-hyperparameters]")).to_be_visible()
    expect(page.get_by_role("link", name="Evaluate")).to_be_visible()
    expect(page.get_by_role("link", name="Clone")).to_have_count(0)
    problems = page_problems(page)

    # A DeepRacer folder without weights: what it creates is shown first; nothing is created.
    archive = tmp_path / "my-deepracer-car.tar.gz"
    archive.write_bytes(deepracer_folder())
    page.goto("/models/import/")
    page.get_by_label("Archive (.tar.gz)").set_input_files(archive)
    page.get_by_role("button", name="Import").click()
    expect(
        page.get_by_role("heading", name="Import a model: check what it creates")
    ).to_be_visible()
    expect(page.locator("[data-preview-notes]")).to_contain_text(
        "the track H_track, which is not loaded here"
    )
    expect(page.locator("[data-preview-track]")).to_have_text("Rookie Loop (counter-clockwise)")
    assert not RLModel.objects.filter(name="my-deepracer-car").exists()
    problems += page_problems(page)
    page.set_viewport_size({"width": 390, "height": 844})  # and on a phone
    problems += page_problems(page)
    page.set_viewport_size({"width": 1280, "height": 800})

    # The racer changes the track (the direction follows what it allows) and confirms.
    track, direction = page.get_by_label("Track"), page.get_by_label("Direction")
    track.select_option(label="Championship Circuit")
    expect(direction.locator("option[value=clockwise]")).to_be_disabled()
    track.select_option(label="Speedway")
    expect(direction.locator("option[value=clockwise]")).to_be_enabled()
    direction.select_option("clockwise")
    page.get_by_label("Maximum training time [min]").fill("30")
    page.get_by_role("button", name="Import and start training").click()
    expect(page.get_by_role("heading", name="my-deepracer-car")).to_be_visible()
    expect(page.get_by_text("its training is queued: up to 30 min on Speedway")).to_be_visible()
    model = RLModel.objects.get(owner=alice, name="my-deepracer-car")
    assert (model.track.name, model.direction, model.max_minutes) == ("speedway", "clockwise", 30)
    off_the_loop(services.training_stop, job=model.latest_job)  # not to train on in the suite
    assert problems == [] and errors == []


def test_the_bell_shows_unread_notifications_and_marks_them_read(page: Page, alice, tracks):
    model = ready_model(alice)
    log_in(page, "alice", PASSWORD)
    bell = page.locator("[data-bell]")
    expect(bell).to_have_attribute("aria-label", "Notifications")
    notifications.notification_send(
        recipient=alice,
        text="straight-ahead finished training: 3 iterations in 1:35.",
        url=f"/models/{model.pk}/",
    )
    notifications.notification_send(recipient=alice, text="Another one.", url="/models/")
    page.reload()
    expect(page.locator("[data-bell-count]")).to_have_text("2")
    expect(bell).to_have_attribute("aria-label", "Notifications, 2 unread")
    bell.click()
    expect(page.get_by_role("heading", name="Notifications")).to_be_visible()
    problems = page_problems(page)
    page.get_by_role("link", name="straight-ahead finished training").click()
    expect(page.get_by_role("heading", name="straight-ahead")).to_be_visible()
    expect(page.locator("[data-bell-count]")).to_have_text("1")
    page.locator("[data-bell]").click()
    page.get_by_role("button", name="Mark all read").click()
    expect(page.get_by_text("Marked 1 notification read.")).to_be_visible()
    expect(page.locator("[data-bell-count]")).to_have_count(0)
    for size in ({"width": 390, "height": 844},):
        page.set_viewport_size(size)
        page.reload()
        problems += page_problems(page)
    assert problems == []
