import re

import pytest
from django.contrib.auth.models import User
from playwright.sync_api import Page, expect

from accounts.models import Profile
from racing.services import demo_season_load
from tests.browser.checks import page_problems
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import expect_seen, log_in, sign_up

pytestmark = pytest.mark.django_db(transaction=True)


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
        "That login name and password do not match. Check both (passwords are case-sensitive) "
        "and try again."
    )
    expect(page.get_by_label("Login name")).to_have_value("alice")


def test_a_visitor_sees_what_pitlane_is_and_the_races_open_now(page: Page, tracks):
    """Its screenshot (test-artifacts/screenshots/) is the one the README shows."""
    demo_season_load()
    page.goto("/")
    expect(page.get_by_role("heading", name="Train a racing car")).to_be_visible()
    races = page.locator(".card h3 a")
    expect(races).to_have_count(3)
    expect(races.first).to_have_text(re.compile(r"Open time trial$"))


def test_on_a_phone_a_racer_who_forgot_their_password_is_told_whom_to_ask_and_edits_a_profile(
    page: Page, alice
):
    page.set_viewport_size({"width": 390, "height": 844})
    page.goto("/accounts/login/")
    page.get_by_role("link", name="Forgot your password?").click()
    expect(page.get_by_text("This console sends no email")).to_be_visible()  # the suite's
    expect(page.get_by_text("Ask your league staff")).to_be_visible()
    assert page_problems(page) == []
    page.get_by_role("link", name="Back to log in").click()

    log_in(page, "alice", PASSWORD)
    page.locator(".nav-account").get_by_role("link", name="alice").click()
    expect(page.get_by_role("heading", name="Your racer profile")).to_be_visible()
    assert page_problems(page) == []
    preview = page.locator("[data-profile-preview]")
    page.get_by_label("Racer name").fill("zoom_z")
    page.get_by_label("Country").select_option("NZ")
    page.get_by_label("Orange").check()
    expect(preview.locator(".racer-name")).to_have_text("zoom_z")  # as the racer types
    expect(preview.locator(".avatar")).to_have_text("Z")
    expect(preview.locator(".avatar")).to_have_class("avatar avatar-orange")
    expect(preview.locator(".racer-country")).to_have_text("NZ")
    expect(preview.locator(".racer-country")).to_have_attribute("title", "New Zealand")

    page.get_by_label("Racer name").fill("zoom z")
    page.get_by_role("button", name="Save profile").click()
    expect(page.locator(".field-error")).to_have_text(
        "A racer name is 2 to 64 letters, digits, hyphens (-) and underscores (_), no spaces."
    )
    expect(page.get_by_label("Racer name")).to_have_value("zoom z")
    expect(page.get_by_label("Country")).to_have_value("NZ")
    assert page_problems(page) == []

    page.get_by_label("Racer name").fill("zoom_z")
    page.get_by_role("button", name="Save profile").click()
    expect(page.get_by_text("Your profile is saved.")).to_be_visible()
    expect(page.locator(".nav-account").get_by_role("link", name="zoom_z")).to_be_visible()
    expect(preview.locator(".avatar")).to_have_class("avatar avatar-orange")
    profile = Profile.objects.get(user=alice)
    assert (profile.racer_name, profile.country, profile.avatar_colour) == (
        "zoom_z",
        "NZ",
        "orange",
    )
    assert page_problems(page) == []


def test_a_racer_makes_a_token_copies_it_once_and_revokes_it(page: Page, alice):
    log_in(page, "alice", PASSWORD)
    page.goto("/accounts/profile/#tokens")
    tokens = page.locator("[data-tokens]")
    expect_seen(tokens.get_by_text("You have no tokens."))
    tokens.get_by_label("Token name").fill("notebook")
    tokens.get_by_label("Read: your models, their training and evaluations, and the league").check()
    expect(tokens.get_by_label("Admin: the league staff's actions (staff only)")).to_have_count(0)
    tokens.get_by_role("button", name="Make the token").click()

    secret = page.locator("[data-secret]")
    expect_seen(secret)
    warning = page.locator("[data-token-secret] p").first
    expect(warning).to_contain_text("Copy your new token now: it is not shown again.")
    expect_seen(warning)
    value = secret.input_value()
    page.context.grant_permissions(["clipboard-read", "clipboard-write"])
    page.get_by_role("button", name="Copy the token").click()
    expect(page.locator("[data-copy-status]")).to_contain_text("Copied")
    assert page.evaluate("navigator.clipboard.readText()") == value
    row = page.locator("[data-token-list] tbody tr")
    expect(row).to_have_count(1)
    expect(row.first).to_contain_text("notebook")
    expect(row.first).to_contain_text(value[:12] + "…")
    expect(row.first.locator("td").nth(4)).to_have_text("never")

    api = page.request.get("/api/v1/me", headers={"Authorization": f"Bearer {value}"})
    assert api.status == 200 and api.json()["token"]["name"] == "notebook"
    page.goto("/accounts/profile/#tokens")  # the page again: its secret is gone
    expect(page.locator("[data-secret]")).to_have_count(0)
    expect(row.first.locator("td").nth(4)).to_have_text(re.compile(" ago$"))

    row.first.get_by_role("button", name="Revoke notebook").click()
    expect_seen(page.get_by_text("Revoked notebook: it no longer works."))
    expect(page.locator("[data-token-list]")).to_have_count(0)
    refused = page.request.get("/api/v1/me", headers={"Authorization": f"Bearer {value}"})
    assert refused.status == 401 and refused.json()["code"] == "unauthenticated"
