"""Reward validations and imports run in a bounded pool of checkers, off the request thread: a
flood of slow reward functions is turned away past the bound, and every other page answers."""

import asyncio
import threading
from urllib.parse import urlencode

import pytest
from asgiref.testing import ApplicationCommunicator
from django.test import Client
from django.urls import reverse

from training import checks

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
    running = checks.pool().submit(release.wait)
    waiting = checks.pool().submit(lambda: "waited")
    with pytest.raises(checks.Busy, match="try again in a few seconds"):
        checks.pool().submit(lambda: "refused")
    release.set()
    assert running.result(timeout=10) is True
    assert waiting.result(timeout=10) == "waited"
    # The places are given back once the work is done: the next check is taken.
    assert checks.pool().submit(lambda: "taken").result(timeout=10) == "taken"


def test_a_check_that_fails_gives_its_place_back(small_pool):
    def broken():
        raise ValueError("broken")

    for _ in range(3):  # more than the pool's places
        with pytest.raises(ValueError, match="broken"):
            checks.pool().submit(broken).result(timeout=10)


def test_every_middleware_runs_on_the_event_loop(caplog, settings):
    """One sync-only middleware would make Django run every view, the async ones included, in a
    server thread: the checkers' awaits would hold one again."""
    from django.core.handlers.asgi import ASGIHandler

    settings.DEBUG = True  # Django says which handlers it adapts only then
    with caplog.at_level("DEBUG", logger="django.request"):
        ASGIHandler()
    assert [r.getMessage() for r in caplog.records if "adapted" in r.getMessage()] == []


async def test_static_files_are_served_on_the_event_loop(browser):
    status, response = await browser.request("GET", "/static/console/site.css")
    assert status == 200
    assert response["headers"]["content-type"].startswith("text/css")


class Browser:
    """Requests to the whole ASGI application, as Daphne hands them over, signed in as a racer."""

    def __init__(self, user) -> None:
        client = Client()
        client.force_login(user)
        self.cookie = f"sessionid={client.cookies['sessionid'].value}; csrftoken={CSRF}"

    async def request(self, method: str, path: str, form: dict | None = None) -> tuple[int, dict]:
        from console.asgi import application

        body = urlencode(form or {}).encode()
        headers = [
            (b"host", b"127.0.0.1"), (b"cookie", self.cookie.encode()),
            (b"x-csrftoken", CSRF.encode()),
            (b"content-type", b"application/x-www-form-urlencoded"),
            (b"content-length", str(len(body)).encode()),
        ]  # fmt: skip
        scope = {
            "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": method,
            "scheme": "http", "path": path, "raw_path": path.encode(), "query_string": b"",
            "root_path": "", "headers": headers, "client": ("127.0.0.1", 5000),
            "server": ("127.0.0.1", 8000),
        }  # fmt: skip
        communicator = ApplicationCommunicator(application, scope)
        await communicator.send_input({"type": "http.request", "body": body})
        start = await communicator.receive_output(timeout=60)
        content = b""
        while True:
            message = await communicator.receive_output(timeout=60)
            content += message.get("body", b"")
            if not message.get("more_body"):
                break
        await communicator.wait(timeout=10)
        headers = {k.decode().lower(): v.decode() for k, v in start.get("headers", [])}
        return start["status"], {"headers": headers, "text": content.decode()}


@pytest.fixture
def browser(alice) -> Browser:
    return Browser(alice)


async def test_slow_validations_past_the_bound_are_refused_and_other_pages_still_answer(
    small_pool, browser, tracks
):
    finished: list[str] = []

    async def validate(n: int):
        form = {"source": SLOW, "track": "rookie-loop"}
        response = await browser.request("POST", reverse("training:reward-validation"), form)
        finished.append(f"validation {n}")
        return response

    validations = [asyncio.create_task(validate(n)) for n in range(4)]
    await asyncio.sleep(0.5)  # all four are in: one checking, one waiting, two refused
    status, page = await browser.request("GET", reverse("training:model-list"))
    finished.append("models page")
    assert status == 200
    assert "Your models" in page["text"]
    results = await asyncio.gather(*validations)

    statuses = sorted(status for status, _ in results)
    assert statuses == [200, 200, 503, 503]
    for status, response in results:
        if status == 503:
            assert "Every checker is busy" in response["text"]
            assert response["headers"]["retry-after"] == str(checks.RETRY_AFTER)
        else:
            assert '"valid": true' in response["text"]
    # The page was served while the checkers still worked on the two slow functions.
    assert finished.index("models page") < max(
        finished.index(f"validation {n}") for n, (status, _) in enumerate(results) if status == 200
    )
