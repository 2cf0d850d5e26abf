"""Reward validations and imports run in a bounded pool of checkers, off the request thread: a
flood of slow reward functions is turned away past the bound, and every other page answers."""

import asyncio
import threading
from urllib.parse import urlencode

import pytest
from django.test import Client
from django.urls import reverse

from tests import asgi
from training import checkers

# The ASGI application serves from its own threads, with connections of their own.
pytestmark = pytest.mark.django_db(transaction=True)

CSRF = "k" * 32  # an unmasked token; the cookie and the header agree

SLOW = """
def reward_function(params):
    total = 0
    for i in range(2000000):
        total += i
    return 1.0
"""


@pytest.fixture
def small_pool(settings):
    settings.PITLANE_CHECKERS = 1
    settings.PITLANE_CHECKS_WAITING = 1
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "validate": "100/m"}


def test_past_the_checkers_and_the_waiting_line_a_check_is_refused_at_once(small_pool):
    release = threading.Event()
    running = checkers.pool().submit(release.wait, racer="alice")
    waiting = checkers.pool().submit(lambda: "waited", racer="bob")
    with pytest.raises(checkers.Busy, match="try again in a few seconds"):
        checkers.pool().submit(lambda: "refused", racer="carol")
    release.set()
    assert running.result(timeout=10) is True
    assert waiting.result(timeout=10) == "waited"
    # The places are given back once the work is done: the next check is taken.
    assert checkers.pool().submit(lambda: "taken", racer="carol").result(timeout=10) == "taken"


def test_a_check_that_fails_gives_its_place_back(small_pool):
    def broken():
        raise ValueError("broken")

    for _ in range(3):  # more than the pool's places
        with pytest.raises(ValueError, match="broken"):
            checkers.pool().submit(broken, racer="alice").result(timeout=10)


@pytest.fixture
def one_checker(settings):
    settings.PITLANE_CHECKERS = 1
    settings.PITLANE_CHECKS_WAITING = 8


class SlowChecks:
    """Checks that record their start and wait for ``release``: a fake of slow reward code."""

    def __init__(self) -> None:
        self.release = threading.Event()
        self.started: list[str] = []

    def submit(self, name: str, racer: str):
        def work():
            self.started.append(name)
            self.release.wait(10)
            return name

        return checkers.pool().submit(work, racer=racer)


def test_a_flooders_waiting_checks_do_not_keep_a_bystander_out(one_checker):
    slow = SlowChecks()
    flood = []
    with pytest.raises(checkers.Busy, match="Your earlier checks are still running"):
        for n in range(20):
            flood.append(slow.submit(f"flood {n}", "flooder"))
    assert len(flood) == checkers.RACER_PLACES  # the waiting line keeps places for others
    bystander = slow.submit("bystander", "bystander")
    slow.release.set()
    assert bystander.result(timeout=10) == "bystander"
    assert [future.result(timeout=10) for future in flood]
    assert slow.started[:2] == ["flood 0", "bystander"]


def test_a_racer_who_waits_is_served_before_any_flooders_next_check(one_checker):
    """Four accounts fill the pool with slow checks; a bystander who comes last is served
    before the second check of any of them: the racers take turns."""
    slow = SlowChecks()
    flooders = ("f1", "f2", "f3", "f4")
    flood = [slow.submit(f"{f} {n}", f) for n in range(checkers.RACER_PLACES) for f in flooders]
    bystander = slow.submit("bystander", "bystander")
    slow.release.set()
    assert [future.result(timeout=10) for future in flood] and bystander.result(timeout=10)
    assert slow.started == [
        "f1 0",
        "f2 0",
        "f3 0",
        "f4 0",
        "bystander",
        "f1 1",
        "f2 1",
        "f3 1",
        "f4 1",
    ]


def test_a_racer_with_nothing_running_goes_before_a_flooder_served_lately(one_checker):
    """Issue 55: a flooder whose check ended before a bystander came went before the bystander
    (their turn was when they came back); now the racer served longest ago goes first."""
    releases: dict[str, threading.Event] = {}
    started: list[str] = []

    def submit(name: str, racer: str):
        releases[name] = threading.Event()

        def work():
            started.append(name)
            releases[name].wait(10)
            return name

        return checkers.pool().submit(work, racer=racer)

    first = submit("f1 a", "f1")
    waiting = submit("f2 a", "f2")
    releases["f1 a"].set()  # f1's check ends; f2's runs
    assert first.result(timeout=10) == "f1 a"
    again = submit("f1 b", "f1")  # f1 comes back before the bystander does
    bystander = submit("bystander", "bystander")
    for event in releases.values():
        event.set()
    assert [f.result(timeout=10) for f in (waiting, again, bystander)]
    assert started == ["f1 a", "f2 a", "bystander", "f1 b"]


def test_a_check_cancelled_while_it_waits_gives_its_place_back(small_pool):
    release = threading.Event()
    running = checkers.pool().submit(release.wait, racer="alice")
    waiting = checkers.pool().submit(lambda: "never", racer="bob")
    assert waiting.cancel()
    assert checkers.pool().submit(lambda: "taken", racer="bob").cancel()  # its place was free
    release.set()
    assert running.result(timeout=10) is True
    assert checkers.pool().submit(lambda: "taken", racer="bob").result(timeout=10) == "taken"


def test_every_middleware_runs_on_the_event_loop(caplog, settings):
    """One sync-only middleware would make Django run every view, the async ones included, in a
    server thread: the checkers' awaits would hold one again."""
    from django.core.handlers.asgi import ASGIHandler

    settings.DEBUG = True  # Django says which handlers it adapts only then
    with caplog.at_level("DEBUG", logger="django.request"):
        ASGIHandler()
    assert [r.getMessage() for r in caplog.records if "adapted" in r.getMessage()] == []


async def test_static_files_are_served_on_the_event_loop(browser):
    response = await browser.request("GET", "/static/console/site.css")
    assert response.status == 200
    assert response.headers["content-type"].startswith("text/css")


class Browser:
    """A racer, signed in, sending forms to the whole ASGI application (``tests.asgi``)."""

    def __init__(self, user) -> None:
        client = Client()
        client.force_login(user)
        self.cookie = f"sessionid={client.cookies['sessionid'].value}; csrftoken={CSRF}"

    async def request(self, method: str, path: str, form: dict | None = None) -> asgi.Response:
        body = urlencode(form or {}).encode()
        headers = {
            "host": "127.0.0.1",
            "cookie": self.cookie,
            "x-csrftoken": CSRF,
            "content-type": "application/x-www-form-urlencoded",
            "content-length": str(len(body)),
        }
        return await asgi.request(method, path, headers, [body], timeout=60)


@pytest.fixture
def browser(alice) -> Browser:
    return Browser(alice)


async def test_slow_validations_past_the_bound_are_refused_and_other_pages_still_answer(
    small_pool, browser, tracks
):
    # Another racer's check holds the one checker until released: no race between the page
    # and the checks decides what the test sees (CI's first version raced them, and a page
    # that took 4 s on a loaded box came after both slow validations).
    release = threading.Event()
    holding = checkers.pool().submit(release.wait, racer="bob")

    async def validate():
        form = {"source": SLOW, "track": "rookie-loop"}
        return await browser.request("POST", reverse("training:reward-validation"), form)

    try:
        validations = [asyncio.create_task(validate()) for _ in range(3)]
        # One place waits for the checker and two are refused at once: once the two refusals
        # are back, the third holds the waiting place.
        done, pending = await asyncio.wait(validations, return_when=asyncio.FIRST_COMPLETED)
        while len(done) < 2:
            more, pending = await asyncio.wait(pending, return_when=asyncio.FIRST_COMPLETED)
            done |= more
        refused = [task.result() for task in done]
        assert [response.status for response in refused] == [503, 503]
        for response in refused:
            assert "Every checker is busy" in response.text
            assert response.headers["retry-after"] == str(checkers.RETRY_AFTER)

        page = await browser.request("GET", reverse("training:model-list"))
        assert page.status == 200
        assert "Your models" in page.text
        (waiting,) = pending
        assert not waiting.done()  # the page was served while the checker was held
    finally:
        release.set()
    assert holding.result(timeout=10) is True
    checked = await waiting
    assert checked.status == 200
    assert '"valid": true' in checked.text
