"""Redis restarted under a live race's open turn: the broadcast and the race page lose their
sockets, open them again once Redis is back, and catch up on what happened while they were
closed; the turn's video resumes; and no websocket handshake after the restart answers 500
(the channel layer's dead pooled connections, issue 55)."""

import asyncio
import io

import pytest
import websockets
from PIL import Image
from playwright.sync_api import Page, expect

from accounts.selectors import racer_name
from common.redis_client import redis_client
from racing import live_races, services
from tests.browser.conftest import off_the_loop
from tests.helpers.accounts import racer
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from training import streams

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.slow]


def jpeg() -> bytes:
    picture = io.BytesIO()
    Image.new("RGB", (32, 18), (200, 40, 40)).save(picture, "JPEG")
    return picture.getvalue()


def frames_shown(page: Page) -> int:
    return int(page.locator("[data-frame]").get_attribute("data-frames") or 0)


def show_a_frame(page: Page, evaluation: int) -> None:
    """Frames of the turn, as its simulation offers them, until the broadcast shows one more."""
    shown = frames_shown(page)
    with streams.FramePublisher(redis_client(), streams.evaluation_group(evaluation)) as frames:
        for _ in range(100):
            frames.offer(streams.frame_event(0, "spectator", jpeg(), episode=0, step=1))
            page.wait_for_timeout(100)
            if frames_shown(page) > shown:
                return
    raise AssertionError("the broadcast showed no new frame of the turn")


async def handshakes(url: str, origin: str, count: int) -> list[int]:
    """The HTTP status of ``count`` websocket handshakes at once (101: switched)."""

    async def one() -> int:
        try:
            async with websockets.connect(url, origin=origin, open_timeout=10) as socket:
                return socket.response.status_code
        except websockets.exceptions.InvalidStatus as refused:
            return refused.response.status_code

    return await asyncio.gather(*(one() for _ in range(count)))


def test_the_broadcast_and_the_race_page_reconnect_and_catch_up_after_redis_restarts(
    page: Page, daphne_server, suite_redis, monkeypatch, alice, bob, stella, tracks
):
    monkeypatch.setattr(services.queueing, "enqueue", lambda *args: None)  # no car drives a turn
    race = event("Restart cup", laps_required=1, laps_to_drive=1)
    carol = racer("carol")
    off_the_loop(scored, race, carol, 61_000)  # a winner to show
    session = off_the_loop(live_races.live_session_open, event=race, facilitator=stella)
    join = live_races.live_entry_join
    off_the_loop(join, session=session, racer=alice, model=ready_model(alice, name="alice-car"))
    evaluation = off_the_loop(live_races.live_turn_launch, session=session).submission.evaluation_id
    bobs = ready_model(bob, name="bob-car")

    screen = page.context.new_page()
    screen.goto(f"/events/{race.slug}/broadcast/")
    page.goto(f"/events/{race.slug}/live/")
    for shown in (screen, page):
        expect(shown.locator("body")).to_have_attribute("data-listening", "true")
    expect(screen.locator("[data-racer]")).to_have_text(racer_name(racer=alice))
    show_a_frame(screen, evaluation)
    # a busy server's pool: several connections in use at once, then idle in the pool
    base = daphne_server.replace("http", "ws")
    off_the_loop(asyncio.run, handshakes(f"{base}/ws/events/{race.pk}/", daphne_server, 8))

    suite_redis.save()  # the data is kept, as make run's Redis keeps it (append-only file)
    suite_redis.stop()
    try:
        for shown in (screen, page):
            expect(shown.locator("body")).to_have_attribute("data-listening", "false")
        # while Redis is down: the organiser shows the winner (its update reaches nobody)
        off_the_loop(services.event_winner_show, event=race)
    finally:
        suite_redis.start()

    for shown in (screen, page):
        expect(shown.locator("body")).to_have_attribute("data-listening", "true")
    expect(screen.locator("[data-winner]")).to_contain_text(racer_name(racer=carol))
    statuses = off_the_loop(
        asyncio.run,
        handshakes(f"{base}/ws/live-turns/{evaluation}/", daphne_server, 8),
    ) + off_the_loop(asyncio.run, handshakes(f"{base}/ws/events/{race.pk}/", daphne_server, 8))
    assert statuses == [101] * 16
    show_a_frame(screen, evaluation)  # the turn's socket watches again
    off_the_loop(join, session=session, racer=bob, model=bobs)  # a queue change, sent now
    expect(page.locator("[data-live-queue] tbody tr")).to_have_count(2)
    expect(page.locator("[data-live-queue]")).to_contain_text(racer_name(racer=bob))
