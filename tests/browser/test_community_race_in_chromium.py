"""A community race in Chromium: the organiser copies the invitation and is asked before taking
a racer out or closing the race; going Back and sending the form again, or a double click, makes
one race; an invitee without an account signs up and comes back to it."""

import re

import pytest
from django.contrib.auth.models import User
from playwright.sync_api import Page, expect

from racing.models import Event
from tests.browser.checks import page_problems
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in, sign_up_here

pytestmark = pytest.mark.django_db(transaction=True)


def organise(page: Page) -> Event:
    page.goto("/races/community/new/")
    page.get_by_label("Name").fill("Friday night")
    page.get_by_role("button", name="Create the race").click()
    expect(page.get_by_role("heading", name=re.compile("Friday night"))).to_be_visible()
    return Event.objects.get(name="Friday night")


def test_an_invitee_signs_up_comes_back_and_joins(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    race = organise(page)
    page.context.clear_cookies()

    page.goto(f"/races/invite/{race.invite_token}/")
    page.get_by_role("link", name="Create a racer account").click()
    sign_up_here(page, "dana")

    expect(page).to_have_url(re.compile(f"/races/invite/{race.invite_token}/$"))
    expect(page.get_by_text("Welcome to Pitlane, dana!")).to_be_visible()
    page.get_by_role("button", name="Join the race").click()
    expect(page.get_by_text("You are in Friday night.")).to_be_visible()
    assert race.participants.filter(username="dana").exists()


def test_the_organiser_copies_the_invitation(page: Page, alice, tracks, daphne_server):
    page.context.grant_permissions(["clipboard-read", "clipboard-write"], origin=daphne_server)
    log_in(page, "alice", PASSWORD)
    race = organise(page)
    race.invite_token = "a_b_c_" + race.invite_token[6:]  # underscores, which were clipped
    race.save(update_fields=["invite_token"])
    page.reload()
    link = page.get_by_role("textbox", name="Invitation link")
    expect(link).to_have_attribute("readonly", "")
    expect(link).to_have_value(f"{daphne_server}/races/invite/{race.invite_token}/")
    # The whole line shows, underscores and all: a sane font and line height, nothing cut off.
    size, line, inner, scrolled = link.evaluate(
        "i => { const s = getComputedStyle(i); const padding = parseFloat(s.paddingTop)"
        " + parseFloat(s.paddingBottom); return [parseFloat(s.fontSize),"
        " parseFloat(s.lineHeight), i.clientHeight - padding, i.scrollHeight - i.clientHeight] }"
    )
    assert size >= 14 and line >= 1.3 * size and inner >= line and scrolled <= 0

    page.get_by_role("button", name="Copy the link").click()
    expect(page.locator("[data-copy-status]")).to_contain_text("Copied")
    copied = page.evaluate("navigator.clipboard.readText()")
    assert copied == f"{daphne_server}/races/invite/{race.invite_token}/"
    page.set_viewport_size({"width": 375, "height": 800})  # a phone
    assert page_problems(page) == []


@pytest.mark.parametrize(
    ("copies", "said"),
    [(True, "Copied: paste it in a message"), (False, "Press Ctrl+C (⌘C on a Mac) to copy")],
)
def test_without_the_clipboard_api_copy_selects_the_link(
    page: Page, alice, tracks, copies: bool, said: str
):
    """Without navigator.clipboard, Copy selects the link and asks execCommand to copy it: the
    page says what its answer means (it is forced here, as browsers differ)."""
    page.add_init_script("Object.defineProperty(navigator, 'clipboard', {value: undefined})")
    page.add_init_script(f"document.execCommand = () => {'true' if copies else 'false'}")
    log_in(page, "alice", PASSWORD)
    organise(page)
    page.get_by_role("button", name="Copy the link").click()
    expect(page.locator("[data-copy-status]")).to_contain_text(said)
    link = page.get_by_role("textbox", name="Invitation link")
    selected = link.evaluate("i => i.value.slice(i.selectionStart, i.selectionEnd)")
    assert selected == link.input_value()


def test_the_organiser_is_asked_before_removing_a_racer_and_closing(page: Page, alice, bob, tracks):
    log_in(page, "alice", PASSWORD)
    race = organise(page)
    race.participants.add(bob)
    page.reload()

    page.get_by_role("button", name="Remove bob").click()
    dialog = page.get_by_role("dialog")
    expect(dialog).to_contain_text("Take bob out of Friday night?")
    dialog.get_by_role("button", name="Cancel").click()
    expect(dialog).to_be_hidden()
    assert race.participants.filter(pk=bob.pk).exists()

    page.get_by_role("button", name="Remove bob").click()
    dialog.get_by_role("button", name="Remove bob").click()
    expect(page.get_by_text("bob is out of Friday night.")).to_be_visible()
    assert not race.participants.filter(pk=bob.pk).exists()
    expect(page.get_by_role("button", name="Let bob back in")).to_be_visible()
    page.get_by_role("button", name="Let bob back in").click()
    expect(page.get_by_text("bob is back in Friday night.")).to_be_visible()
    assert race.participants.filter(pk=bob.pk).exists()

    page.get_by_role("button", name="Close the race now").click()
    expect(dialog).to_contain_text("Close Friday night now?")
    dialog.get_by_role("button", name="Close the race").click()
    expect(page.get_by_text("Friday night is closed")).to_be_visible()
    race.refresh_from_db()
    assert race.state == Event.State.CLOSED


def test_the_race_form_shows_only_the_fields_of_the_race_type(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/races/community/new/")
    expect(page.get_by_label("Boxes", exact=True)).to_be_hidden()
    expect(page.get_by_label("Bot cars", exact=True)).to_be_hidden()
    page.get_by_label("Race type").select_option(label="Object avoidance")
    expect(page.get_by_label("Boxes", exact=True)).to_be_visible()
    expect(page.get_by_label("Bot cars", exact=True)).to_be_hidden()
    page.get_by_label("Race type").select_option(label="Head-to-bot")
    expect(page.get_by_label("Boxes", exact=True)).to_be_hidden()
    expect(page.get_by_label("Bot cars", exact=True)).to_be_visible()
    expect(page.locator(".track-choice img").first).to_be_visible()
    assert User.objects.count() == 1


def test_back_and_submit_again_or_a_double_click_makes_one_race(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    race = organise(page)
    page.go_back()
    expect(page.get_by_label("Name")).to_have_value("Friday night")
    page.get_by_role("button", name="Create the race").click()
    same = page.get_by_text("You created Friday night with these settings a moment ago")
    expect(same).to_be_visible()
    expect(page).to_have_url(re.compile(f"/races/community/{race.slug}/$"))
    assert Event.objects.filter(name="Friday night").count() == 1

    page.goto("/races/community/new/")
    page.get_by_label("Name").fill("Saturday")
    page.get_by_role("button", name="Create the race").dblclick()
    expect(page.get_by_role("heading", name=re.compile("Saturday"))).to_be_visible()
    assert Event.objects.filter(name="Saturday").count() == 1


def test_the_organiser_deletes_a_race_nobody_entered_after_a_confirmation(
    page: Page, alice, tracks
):
    log_in(page, "alice", PASSWORD)
    race = organise(page)
    page.set_viewport_size({"width": 390, "height": 844})
    page.get_by_role("link", name="Delete the race").click()
    expect(page.get_by_role("heading", name="Delete Friday night?")).to_be_visible()
    assert page_problems(page) == []
    page.get_by_role("button", name="Delete Friday night").click()
    expect(page.get_by_text("Friday night is deleted.")).to_be_visible()
    expect(page).to_have_url(re.compile("/races/$"))
    assert not Event.objects.filter(pk=race.pk).exists()
