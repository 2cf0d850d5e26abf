"""A live race in Chromium: two racers join the queue from the race page, the facilitator
reorders it and launches a turn, which a real simulation worker drives in real time while the
race page and the broadcast show it, uncovered; its lap reads the same on the race page, the
broadcast, the leaderboard and the submission page; the winner shown stays shown on a reloaded
broadcast; and the race page fits a phone."""

import pytest
from playwright.sync_api import Page, expect

from accounts.selectors import racer_name
from common.formatting import laptime
from racing.models import Submission
from tests.browser.checks import page_problems
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import expect_seen, log_in
from tests.helpers.league import event
from tests.helpers.models import ready_model

pytestmark = [
    pytest.mark.django_db(transaction=True),
    pytest.mark.usefixtures("celery_worker_process"),
]


def racer_page(page: Page, base_url: str, username: str) -> Page:
    """``username``'s own browser, logged in."""
    context = page.context.browser.new_context(base_url=base_url)
    context.set_default_timeout(15_000)
    own = context.new_page()
    log_in(own, username, PASSWORD)
    return own


def test_two_racers_queue_the_facilitator_reorders_and_a_turn_drives_live(
    page: Page, daphne_server, alice, bob, stella, tracks
):
    race = event("Live cup", laps_required=1, laps_to_drive=1)
    models = {"alice": ready_model(alice, name="alice-straight")}
    models["bob"] = ready_model(bob, name="bob-straight")
    live = f"/events/{race.slug}/live/"

    log_in(page, "stella", PASSWORD)
    page.goto(live)
    page.get_by_role("button", name="Open the live race").click()
    expect(page.get_by_text("Nobody is in the queue yet.")).to_be_visible()

    screen = page.context.new_page()
    screen.set_viewport_size({"width": 1920, "height": 1080})  # a projector
    screen.goto(f"/events/{race.slug}/broadcast/")
    expect(screen.locator("body")).to_have_attribute("data-listening", "true")
    expect_seen(screen.locator("[data-racer]"))  # nothing over the picture until the winner
    expect(screen.locator("[data-winner]")).to_be_hidden()

    for username, model in models.items():
        own = racer_page(page, daphne_server, username)
        own.goto(live)
        own.get_by_label("Model").select_option(str(model.pk))
        own.get_by_label("Speed multiplier").fill("1.2")
        own.get_by_role("button", name="Join the queue").click()
        expect(own.get_by_text("You are in the queue")).to_be_visible()
    watcher = own  # bob's page stays open, watching

    rows = page.locator("[data-live-queue] tbody tr")
    page.reload()
    expect(rows).to_have_count(2)
    expect(rows.nth(0)).to_contain_text(racer_name(racer=alice))
    page.get_by_role("button", name=f"Move {racer_name(racer=bob)} up").click()
    expect(rows.nth(0)).to_contain_text(racer_name(racer=bob))

    page.set_viewport_size({"width": 1366, "height": 850})  # a laptop at the track
    expect_seen(page.get_by_role("button", name="Launch the next turn"))
    expect_seen(page.locator("[data-turn-timer]"))  # the car's timer above the fold
    page.get_by_role("button", name="Launch the next turn").click()
    expect(page.get_by_text("bob-straight is on the track.")).to_be_visible()
    expect(watcher.locator("[data-turn-racer]")).to_contain_text(racer_name(racer=bob))
    expect(screen.locator("[data-racer]")).to_have_text(racer_name(racer=bob))
    # the worker drives it: its frames reach the race page and the broadcast as it goes
    expect(watcher.locator("[data-turn-frame]")).to_be_visible(timeout=60_000)
    expect(screen.locator("[data-frame]")).to_be_visible()

    done = watcher.locator("[data-live-queue] tr[data-status=done]")
    expect(done).to_contain_text(racer_name(racer=bob), timeout=90_000)
    submission = Submission.objects.get(event=race, racer=bob)
    assert submission.status == Submission.Status.COMPLETED and submission.qualified
    assert submission.evaluation.real_time and submission.evaluation.speed_multiplier == 1.2
    expect(watcher.locator("[data-turn-laps] li")).to_have_count(1)
    expect(screen.locator("[data-top] li").first).to_contain_text(racer_name(racer=bob))
    expect_seen(screen.locator("[data-top] li").first)
    # one lap, with its off-track penalties inside its time: the same figure on every page
    lap = submission.laps.get()
    assert lap.off_tracks and lap.penalty_ms, "the straight model leaves the oval at its bends"
    shown = laptime(lap.time_ms)
    listed = f"{shown} ({lap.off_tracks} off-track{'s' if lap.off_tracks > 1 else ''})"
    expect(watcher.locator("[data-turn-laps] li")).to_have_text(listed)
    expect(screen.locator("[data-laps] li")).to_have_text(listed)
    expect(watcher.locator("[data-turn-timer]")).to_have_text(shown)

    page.get_by_role("button", name="Show the winner on the broadcast").click()
    winner = screen.locator("[data-winner]")
    expect(winner).to_contain_text(racer_name(racer=bob))
    expect_seen(screen.locator("[data-winner-racer]"))
    screen.reload()  # a broadcast opened after the winner was shown shows it too
    expect_seen(screen.locator("[data-winner-racer]"))
    expect(winner).to_contain_text(f"bob-straight · {laptime(submission.score_ms)}")

    watcher.goto(race.get_absolute_url())
    expect(watcher.locator("tbody tr").first).to_contain_text(racer_name(racer=bob))
    expect(watcher.locator("tbody tr").first).to_contain_text(laptime(submission.score_ms))
    watcher.goto(submission.get_absolute_url())
    expect(watcher.locator("tr[data-lap='1'] [data-lap-time]")).to_have_text(shown)

    watcher.set_viewport_size({"width": 390, "height": 844})  # a racer's phone
    watcher.goto(live)
    assert page_problems(watcher) == []  # the queue scrolls in its card, the page fits
    expect_seen(watcher.locator("[data-turn-timer]"))
