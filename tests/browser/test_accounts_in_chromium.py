import re

import pytest
from django.contrib.auth.models import User
from playwright.sync_api import Page, expect

from racing.services import demo_season_load
from tests.conftest import PASSWORD

pytestmark = pytest.mark.django_db(transaction=True)


def log_in(page: Page, username: str, password: str) -> None:
    page.goto("/accounts/login/")
    page.get_by_label("Racer name").fill(username)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Log in").click()


def sign_up(page: Page, username: str) -> None:
    """From the home page, as a visitor finds it."""
    page.get_by_role("link", name="Create your racer account").click()
    page.get_by_label("Racer name").fill(username)
    page.get_by_label("Password", exact=True).fill(PASSWORD)
    page.get_by_label("Password confirmation").fill(PASSWORD)
    page.get_by_role("button", name="Sign up").click()


def test_a_new_racer_signs_up_logs_out_and_logs_back_in(page: Page):
    page.goto("/")
    sign_up(page, "dana")

    expect(page.get_by_role("heading", name="Welcome to Pitlane, dana")).to_be_visible()
    expect(page.get_by_text("Welcome")).to_have_count(1)  # one greeting
    expect(page.get_by_role("heading", name="Your next steps")).to_be_visible()
    expect(
        page.get_by_role("navigation", name="Main").get_by_role("link", name="Models")
    ).to_be_visible()
    assert User.objects.filter(username="dana").exists()

    page.get_by_role("button", name="Log out").click()
    expect(page.get_by_role("link", name="Create your racer account")).to_be_visible()

    log_in(page, "dana", PASSWORD)
    expect(page.get_by_role("heading", name="Welcome back, dana")).to_be_visible()


def test_a_wrong_password_gets_a_clear_message_in_the_browser(page: Page, alice):
    log_in(page, "alice", "not-my-password")
    expect(page.get_by_role("alert")).to_have_text(
        "That racer name and password do not match. Check both (passwords are case-sensitive) "
        "and try again."
    )
    expect(page.get_by_label("Racer name")).to_have_value("alice")


def test_a_visitor_sees_what_pitlane_is_and_the_races_open_now(page: Page, tracks):
    """Its screenshot (test-artifacts/screenshots/) is the one the README shows."""
    demo_season_load()
    page.goto("/")
    expect(page.get_by_role("heading", name="Train a racing car")).to_be_visible()
    races = page.locator(".card h3 a")
    expect(races).to_have_count(3)
    expect(races.first).to_have_text(re.compile(r"Open time trial$"))
