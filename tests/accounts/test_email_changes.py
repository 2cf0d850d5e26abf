"""A racer's email address changes only with their password, belongs to one account, and where
the console sends email, takes over only once the link sent to the new address is followed."""

import re
from datetime import timedelta

import pytest
from django.contrib.auth.models import User
from django.core import mail
from django.urls import reverse
from django.utils import timezone

from accounts import tasks
from accounts.models import Profile
from tests.helpers.accounts import PASSWORD

pytestmark = pytest.mark.django_db


@pytest.fixture
def by_email(settings):
    """The console names an email server; the suite's backend keeps what is sent in
    mail.outbox."""
    settings.PITLANE_PASSWORD_RESET_BY_EMAIL = settings.PITLANE_EMAIL_NOTIFICATIONS = True
    settings.PITLANE_SITE_URL = "https://pitlane.example.org"


def with_address(racer: User, email: str) -> User:
    racer.email = email
    racer.save(update_fields=["email"])
    return racer


def profile_form(**fields) -> dict:
    return {"racer_name": "Alice_R", "country": "NZ", "avatar_colour": "purple", **fields}


def change_email(client, email: str, password: str = PASSWORD, **fields):
    return client.post(
        reverse("accounts:profile"), profile_form(email=email, password=password, **fields)
    )


def link_in(message) -> str:
    return re.search(r"https://pitlane\.example\.org(/\S+)", message.body).group(1)


def request_change(client, django_capture_on_commit_callbacks, email: str) -> str:
    """Ask for ``email`` on the logged-in racer's profile; the path of the link sent to it."""
    with django_capture_on_commit_callbacks(execute=True):
        assert change_email(client, email).status_code == 302
    (link,) = [message for message in mail.outbox if message.to == [email]]
    return link_in(link)


def test_a_wrong_password_changes_nothing_and_keeps_what_was_typed(client, alice):
    with_address(alice, "alice@example.org")
    client.force_login(alice)
    response = change_email(client, "thief@example.org", password="guess", racer_name="Zed_1")
    assert response.status_code == 400
    assert "That is not your current password, so nothing was saved." in response.text
    assert 'value="Zed_1"' in response.text and 'value="thief@example.org"' in response.text
    assert 'value="guess"' not in response.text  # a password is never sent back
    alice.refresh_from_db()
    assert alice.email == "alice@example.org" and alice.profile.racer_name == "alice"
    assert alice.profile.pending_email == ""


def test_changing_the_address_without_the_password_asks_for_it(client, alice):
    client.force_login(alice)
    response = change_email(client, "alice@example.org", password="")
    assert response.status_code == 400
    assert "Enter your current password to change your email address." in response.text
    assert User.objects.get(pk=alice.pk).email == ""


def test_the_other_fields_save_without_the_password_while_the_address_stays(client, alice):
    with_address(alice, "alice@example.org")
    client.force_login(alice)
    assert change_email(client, "alice@example.org", password="").status_code == 302
    assert Profile.objects.get(user=alice).racer_name == "Alice_R"


@pytest.mark.parametrize("address", ["bob@example.org", "Bob@EXAMPLE.org"])
def test_an_address_of_another_account_is_refused_whatever_its_capitals(
    client, alice, bob, address, by_email
):
    with_address(bob, "bob@example.org")
    client.force_login(alice)
    response = change_email(client, address)
    assert response.status_code == 400
    assert "That address belongs to another account." in response.text
    assert Profile.objects.get(user=alice).pending_email == "" and mail.outbox == []


def test_without_email_the_address_is_saved_at_once_and_nothing_is_sent(client, alice):
    with_address(alice, "old@example.org")
    client.force_login(alice)
    response = client.post(
        reverse("accounts:profile"),
        profile_form(email="new@example.org", password=PASSWORD),
        follow=True,
    )
    assert "Your profile is saved." in response.text
    assert User.objects.get(pk=alice.pk).email == "new@example.org" and mail.outbox == []


def test_the_link_sent_to_a_new_address_makes_it_the_racers_once(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    with_address(alice, "old@example.org")
    client.force_login(alice)
    with django_capture_on_commit_callbacks(execute=True):
        saved = client.post(
            reverse("accounts:profile"),
            profile_form(email="New@Example.ORG", password=PASSWORD),
            follow=True,
        )
    assert "To make New@example.org your email address, follow the link" in saved.text
    assert "until then, email still goes to old@example.org" in saved.text
    assert "Waiting for confirmation: <strong>New@example.org</strong>" in saved.text
    assert User.objects.get(pk=alice.pk).email == "old@example.org"  # not yet

    link_message, notice = sorted(
        mail.outbox, key=lambda message: message.to != ["New@example.org"]
    )
    assert link_message.to == ["New@example.org"]
    assert "log in as alice and open this link (it works once, for 3 days)" in link_message.body
    assert notice.to == ["old@example.org"]
    assert notice.subject == "Pitlane: your email address is being changed"
    assert "still come here" in notice.body and "New@example.org" not in notice.body
    link = link_in(link_message)

    page = client.get(link)
    assert page.status_code == 200 and "Make <strong>New@example.org</strong>" in page.text
    assert User.objects.get(pk=alice.pk).email == "old@example.org"  # a look changes nothing
    done = client.post(link, follow=True)
    assert "New@example.org is now your email address." in done.text
    assert User.objects.get(pk=alice.pk).email == "New@example.org"
    assert Profile.objects.get(user=alice).pending_email == ""

    again = client.post(link)
    assert again.status_code == 400 and "This link no longer works" in again.text
    assert client.get(link).status_code == 400


def test_the_token_is_stored_hashed(client, alice, by_email, django_capture_on_commit_callbacks):
    client.force_login(alice)
    link = request_change(client, django_capture_on_commit_callbacks, "new@example.org")
    token = link.rstrip("/").rsplit("/", 1)[1]
    stored = Profile.objects.get(user=alice).pending_email_token
    assert len(stored) == 64 and token not in stored


def test_an_expired_link_is_refused_in_words(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    with_address(alice, "old@example.org")
    client.force_login(alice)
    link = request_change(client, django_capture_on_commit_callbacks, "new@example.org")
    Profile.objects.filter(user=alice).update(
        pending_email_sent_at=timezone.now() - timedelta(days=3, minutes=1)
    )
    response = client.post(link)
    assert response.status_code == 400
    assert "This link has expired: a confirmation link works for 3 days." in response.text
    assert User.objects.get(pk=alice.pk).email == "old@example.org"
    assert Profile.objects.get(user=alice).pending_email == ""


def test_another_racers_link_does_not_work_for_you(
    client, alice, bob, by_email, django_capture_on_commit_callbacks
):
    client.force_login(alice)
    alices_link = request_change(client, django_capture_on_commit_callbacks, "new@example.org")
    client.force_login(bob)
    response = client.post(alices_link)
    assert response.status_code == 400 and "This link no longer works" in response.text
    assert User.objects.get(pk=bob.pk).email == "" == User.objects.get(pk=alice.pk).email
    assert Profile.objects.get(user=alice).pending_email == "new@example.org"  # still hers


def test_a_link_must_be_followed_logged_in(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    client.force_login(alice)
    link = request_change(client, django_capture_on_commit_callbacks, "new@example.org")
    client.logout()
    response = client.post(link)
    assert response.status_code == 302 and response.url.startswith(reverse("login"))
    assert User.objects.get(pk=alice.pk).email == ""


def test_a_newer_link_replaces_the_older_one(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    client.force_login(alice)
    first = request_change(client, django_capture_on_commit_callbacks, "one@example.org")
    second = request_change(client, django_capture_on_commit_callbacks, "two@example.org")
    assert "This link no longer works" in client.post(first).text
    assert Profile.objects.get(user=alice).pending_email == "two@example.org"  # left alone
    client.post(second)
    assert User.objects.get(pk=alice.pk).email == "two@example.org"


def test_an_address_another_account_took_meanwhile_is_refused_at_the_link(
    client, alice, bob, by_email, django_capture_on_commit_callbacks
):
    client.force_login(alice)
    link = request_change(client, django_capture_on_commit_callbacks, "shared@example.org")
    with_address(bob, "SHARED@example.org")
    response = client.post(link)
    assert response.status_code == 400
    assert "That address now belongs to another account" in response.text
    assert User.objects.get(pk=alice.pk).email == ""


def test_a_reset_link_goes_to_the_verified_address_only(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    with_address(alice, "old@example.org")
    client.force_login(alice)
    request_change(client, django_capture_on_commit_callbacks, "new@example.org")
    mail.outbox.clear()

    tasks.password_reset_email("new@example.org")  # the worker's half of "Forgot your password?"
    assert mail.outbox == []
    tasks.password_reset_email("old@example.org")
    (reset,) = mail.outbox
    assert reset.to == ["old@example.org"] and reset.subject == "Pitlane: set a new password"


def test_removing_the_address_needs_the_password_and_tells_the_old_one(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    with_address(alice, "old@example.org")
    client.force_login(alice)
    assert change_email(client, "", password="guess").status_code == 400
    with django_capture_on_commit_callbacks(execute=True):
        assert change_email(client, "").status_code == 302
    assert User.objects.get(pk=alice.pk).email == ""
    (notice,) = mail.outbox
    assert notice.to == ["old@example.org"] and "was removed" in notice.body


def test_staff_cannot_give_one_racers_address_to_another_in_the_admin(client, alice, bob, stella):
    with_address(bob, "bob@example.org")
    stella.is_superuser = True
    stella.save()
    client.force_login(stella)
    url = reverse("admin:auth_user_change", args=[alice.pk])
    form = {
        "username": "alice",
        "email": "BOB@example.org",
        "is_active": "on",
        "date_joined_0": "2026-11-29",
        "date_joined_1": "04:00:00",
        "profile-TOTAL_FORMS": "1",
        "profile-INITIAL_FORMS": "1",
        "profile-MIN_NUM_FORMS": "0",
        "profile-MAX_NUM_FORMS": "1",
        "profile-0-id": str(alice.profile.pk),
        "profile-0-user": str(alice.pk),
        "profile-0-racer_name": "alice",
        "profile-0-country": "",
        "profile-0-avatar_colour": "teal",
    }
    response = client.post(url, form)
    assert (
        response.status_code == 200 and "That address belongs to another account." in response.text
    )
    assert User.objects.get(pk=alice.pk).email == ""
    assert client.post(url, {**form, "email": "alice@example.org"}).status_code == 302
    assert User.objects.get(pk=alice.pk).email == "alice@example.org"


@pytest.mark.parametrize("password", ["", "guess"])
def test_without_the_right_password_the_page_says_nothing_of_who_has_an_address(
    client, alice, bob, password
):
    with_address(bob, "bob@example.org")
    client.force_login(alice)
    response = change_email(client, "bob@example.org", password=password)
    assert response.status_code == 400
    assert "That address belongs to another account." not in response.text
    assert "password" in response.text


def test_typing_the_current_address_again_cancels_a_pending_change(
    client, alice, by_email, django_capture_on_commit_callbacks
):
    with_address(alice, "alice@example.org")
    client.force_login(alice)
    link = request_change(client, django_capture_on_commit_callbacks, "new@example.org")
    assert change_email(client, "alice@example.org", password="").status_code == 302
    assert Profile.objects.get(user=alice).pending_email == ""
    assert "This link no longer works" in client.post(link).text
    assert User.objects.get(pk=alice.pk).email == "alice@example.org"
