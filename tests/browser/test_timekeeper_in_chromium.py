"""A physical event in Chromium: the timekeeper picks the racer by racer name from what they
type, records a real car's laps by keyboard, undoes a mistaken crossing, strikes a lap out and
restores it, finishes the run; the broadcast page follows it live and ranks it, and the open
leaderboard takes the run at once, marked as a real car's."""

import json
import re
import threading

import pytest
from playwright.sync_api import Page, expect
from websockets.sync.server import serve

from accounts.selectors import racer_name
from common.formatting import laptime
from racing.models import RankingMethod, Submission
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import expect_seen, log_in
from tests.helpers.league import event

pytestmark = pytest.mark.django_db(transaction=True)
LAP = 1_100  # [ms] between crossings: the event's shortest lap is a second


def test_the_timekeeper_times_a_real_car_by_keyboard_and_the_broadcast_follows(
    page: Page, alice, stella, tracks
):
    race = event(
        "Summit live",
        physical=True,
        laps_required=2,
        laps_to_drive=3,
        ranking_method=RankingMethod.BEST_LAP,
        off_track_penalty_s=2.0,
        min_lap_s=1.0,
        race_time_min=2,
    )
    alice.profile.racer_name = "VeraFast"  # her login name, alice, is nobody's business
    alice.profile.save(update_fields=["racer_name"])
    screen = page.context.new_page()
    screen.goto(f"/events/{race.slug}/broadcast/")
    expect(screen.locator("body")).to_have_attribute("data-listening", "true")
    expect(screen.locator("[data-racer]")).to_have_text("Waiting for the next car")

    log_in(page, "stella", PASSWORD)
    page.goto(f"/events/{race.slug}/timekeeper/")
    page.get_by_label("Racer").fill("vera")  # the racer search suggests her racer name
    suggestion = page.locator("[data-racer-suggestions]").get_by_role("button", name="VeraFast")
    expect_seen(suggestion)
    suggestion.click()
    expect(page.get_by_label("Racer")).to_have_value("VeraFast")
    page.get_by_label("Model").fill("sim2real-v3")
    page.get_by_label("Car number").fill("7")
    page.get_by_role("button", name="Put the car on the track").click()
    keeper = page.locator("[data-timekeeper]")
    expect(page.locator("[data-on-track]")).to_be_visible()
    expect(page.locator("body")).to_have_attribute("data-listening", "true")
    name = racer_name(racer=alice)
    expect(screen.locator("[data-racer]")).to_have_text(name)
    expect_seen(screen.locator("[data-racer]"))  # no winner layer over the race

    page.keyboard.press(" ")  # the car crosses the line: the clock starts
    expect(page.locator("[data-waiting]")).to_be_hidden()
    left = re.compile(r"^(1:5\d|2:00)$")  # the racer's two minutes, counting down
    for watched in (page, screen):
        expect(watched.locator("[data-race-left]")).to_have_text(left)
        expect_seen(watched.locator("[data-race-time]"))
    page.wait_for_timeout(LAP)
    page.keyboard.press(" ")
    expect(keeper).to_have_attribute("data-laps", "1")
    page.keyboard.press("o")  # an off-track on lap 2
    expect(page.locator("[data-off-tracks]")).to_have_text("1")
    page.wait_for_timeout(LAP)
    page.keyboard.press(" ")
    expect(keeper).to_have_attribute("data-laps", "2")
    expect(screen.locator("ol[data-laps] li")).to_have_count(2)
    page.keyboard.press("u")  # that crossing was a mistake: lap 2 runs on, its off-track with it
    expect(keeper).to_have_attribute("data-laps", "1")
    expect(page.locator("[data-off-tracks]")).to_have_text("1")
    expect(screen.locator("ol[data-laps] li")).to_have_count(1)
    page.wait_for_timeout(LAP)
    page.keyboard.press(" ")
    expect(keeper).to_have_attribute("data-laps", "2")

    # lap 1 struck out from its row, then restored: a person sees which laps count
    first = page.locator("tbody[data-laps] tr").first
    page.get_by_role("button", name="Strike lap 1 out").click()
    expect_seen(first.get_by_text("no: struck out"))
    page.get_by_role("button", name="Restore lap 1").click()
    expect_seen(page.get_by_role("button", name="Strike lap 1 out"))
    # counted again, and flagged: 1.1 s against lap 2's 4.4 s (2 s of it the off-track's penalty)
    expect(first.locator("td").nth(5)).to_have_text(re.compile("^yes · far below the others"))
    expect_seen(first.locator("td").nth(5))

    board = page.context.new_page()  # the leaderboard, open before the run is scored
    board.goto(race.get_absolute_url())
    expect(board.locator("body")).to_have_attribute("data-listening", "true")
    page.once("dialog", lambda dialog: dialog.accept())
    page.keyboard.press("f")
    result = page.locator("[data-last-result]")
    expect(result).to_have_text(re.compile(f"^{name}'s run scored"))
    expect_seen(result.get_by_role("link", name="Edit this run's laps"))
    submission = Submission.objects.get(event=race, racer=alice)
    laps = list(submission.laps.order_by("number"))
    assert submission.physical and submission.score_ms == min(lap.time_ms for lap in laps)
    assert laps[1].off_tracks == 1 and laps[1].penalty_ms == 2_000
    assert laps[1].time_ms - laps[1].penalty_ms >= 2 * LAP  # from lap 1's end, through the undo

    top = screen.locator("[data-top] li")
    expect(top).to_have_count(1)
    expect(top.first).to_contain_text(name)
    expect(top.first).to_contain_text("real car")
    # each lap's one time, its penalty inside, on the timekeeper's page and the broadcast
    shown = [laptime(lap.time_ms) for lap in laps]
    expect(page.locator("tbody[data-laps] tr td:nth-child(2)")).to_have_text(shown)
    expect(screen.locator("ol[data-laps] li")).to_have_text([shown[0], f"{shown[1]} (1 off-track)"])
    page.get_by_role("button", name="Show the winner on the broadcast").click()
    expect_seen(screen.locator("[data-winner-racer]"))
    expect(screen.locator("[data-winner-racer]")).to_have_text(name)
    screen.reload()  # the projector reloaded after the final still shows the winner
    expect_seen(screen.locator("[data-winner-racer]"))

    # the leaderboard heard the ranking and fetched its table again, without a reload
    expect(board.locator("[data-physical]")).to_have_text("Real car")
    expect(board.locator("[data-leaderboard]")).to_have_attribute("data-updates", "1")
    expect(board.locator("tbody tr").first).to_contain_text(laptime(submission.score_ms))
    board.goto(submission.get_absolute_url())  # the racer's own page: the same laps
    for number, time in enumerate(shown, start=1):
        expect(board.locator(f"tr[data-lap='{number}'] [data-lap-time]")).to_have_text(time)


class LapTimer:
    """DREM's Raspberry Pi lap timer as the page meets it: a websocket server that greets each
    client, then sends each crossing its gates see (leaderboard-timer/timer.js:99-117, 232-241)."""

    def __init__(self) -> None:
        self.clients: list = []
        self.server = serve(self._greet, "127.0.0.1", 0)
        self.url = f"ws://127.0.0.1:{self.server.socket.getsockname()[1]}"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def _greet(self, client) -> None:
        client.send(json.dumps({"event": "connected", "timestamp": 0, "serverInfo": {}}))
        self.clients.append(client)
        for _ in client:  # DREM's timer reads nothing; held open until the page goes
            pass

    def lap(self, at_ms: int) -> None:
        for client in self.clients:
            client.send(json.dumps({"event": "lap", "timestamp": at_ms, "gpio": 17}))


def test_the_timekeeper_page_listens_to_drems_lap_timer_and_its_laps_count(
    page: Page, alice, stella, tracks
):
    race = event("Club night", physical=True, laps_to_drive=3, min_lap_s=1.0)
    timer = LapTimer()
    try:
        log_in(page, "stella", PASSWORD)
        page.goto(f"/events/{race.slug}/timekeeper/")
        page.get_by_label("Racer").fill(racer_name(racer=alice))
        page.get_by_label("Model").fill("sim2real-v3")
        page.get_by_label("Car number").fill("3")
        page.get_by_role("button", name="Put the car on the track").click()
        expect(page.locator("[data-on-track]")).to_be_visible()
        page.get_by_label("Timer address").fill(timer.url)
        page.get_by_role("button", name="Listen to the timer").click()
        status = page.locator("[data-lap-timer-status]")
        expect(status).to_have_text(
            f"Listening to the lap timer at {timer.url}: each lap it sees is a crossing."
        )
        status.scroll_into_view_if_needed()  # under the button pressed, at the page's foot
        expect_seen(status)

        timer.lap(1_795_900_010_000)  # the car crosses the line: the clock starts
        expect(page.locator("[data-waiting]")).to_be_hidden()
        timer.lap(1_795_900_018_123)
        keeper = page.locator("[data-timekeeper]")
        expect(keeper).to_have_attribute("data-laps", "1")
        lap = page.locator("tbody[data-laps] tr td").nth(1)
        expect(lap).to_have_text(laptime(8_123))
        # Back up to the laps, from the timer's panel: by their table, which stays while each
        # state the page is sent draws its rows anew (a row's handle may be gone by then).
        page.locator("table:has(tbody[data-laps])").scroll_into_view_if_needed()
        expect_seen(lap)
        timer.lap(1_795_900_018_400)  # the second gate, 0.3 s later: a double, refused in words
        expect(page.locator("[data-error]")).to_contain_text("shortest lap")
        assert Submission.objects.get(event=race).laps.count() == 1
    finally:
        timer.server.shutdown()
