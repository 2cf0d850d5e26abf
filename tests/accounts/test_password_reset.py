import re

import pytest
from django.contrib.auth.models import User
from django.core import mail
from django.db import transaction
from django.urls import reverse

from accounts import tasks
from tests.helpers.accounts import PASSWORD

pytestmark = pytest.mark.django_db

NEW_PASSWORD = "a-fresh-lap-of-the-oval-42"


@pytest.fixture
def by_email(settings):
    """The site names an email server; the suite's backend keeps what is sent in mail.outbox."""
    settings.PITLANE_PASSWORD_RESET_BY_EMAIL = True
    settings.PITLANE_SITE_URL = "https://pitlane.example.org"


@pytest.fixture
def worker(monkeypatch):
    """A worker that sends each reset email the moment its request commits (at once: the test's
    transaction never commits)."""
    monkeypatch.setattr(tasks.password_reset_email, "delay", tasks.password_reset_email)
    monkeypatch.setattr(transaction, "on_commit", lambda queue, *args, **kwargs: queue())


def test_the_log_in_page_offers_a_way_back_in_for_a_forgotten_password(client):
    page = client.get(reverse("login")).text
    assert f'<a href="{reverse("password_reset")}">Forgot your password?</a>' in page


def test_a_racer_gets_a_reset_link_by_email_and_it_sets_a_new_password(
    client, alice, by_email, worker
):
    alice.email = "alice@example.org"
    alice.save()
    response = client.post(reverse("password_reset"), {"email": "Alice@Example.org"}, follow=True)
    assert "Check your email" in response.text

    (email,) = mail.outbox
    assert email.to == ["alice@example.org"] and email.subject == "Pitlane: set a new password"
    assert "Hello alice," in email.body and "You log in as: alice" in email.body
    assert "it works once, for 2 hours" in email.body
    link = re.search(r"https://pitlane\.example\.org(/\S+)", email.body).group(1)

    form = client.get(link, follow=True)
    assert "Set a new password" in form.text and "<strong>alice</strong>" in form.text
    done = client.post(
        form.redirect_chain[-1][0],
        {"new_password1": NEW_PASSWORD, "new_password2": NEW_PASSWORD},
        follow=True,
    )
    assert "Your new password is set" in done.text
    assert client.login(username="alice", password=NEW_PASSWORD)
    assert not User.objects.get(pk=alice.pk).check_password(PASSWORD)

    client.logout()
    again = client.get(link, follow=True)  # a link works once
    assert "This link no longer works" in again.text


def test_the_reset_page_says_the_same_whether_or_not_an_account_has_the_address(
    client, alice, by_email, worker
):
    alice.email = "alice@example.org"
    alice.save()
    known = client.post(reverse("password_reset"), {"email": "alice@example.org"})
    unknown = client.post(reverse("password_reset"), {"email": "nobody@example.org"})
    assert known.status_code == unknown.status_code == 302
    assert known.url == unknown.url == reverse("password_reset_done")
    assert len(mail.outbox) == 1


def test_the_request_sends_nothing_itself_and_queues_the_same_task_either_way(
    client, alice, by_email, monkeypatch, django_capture_on_commit_callbacks
):
    alice.email = "alice@example.org"
    alice.save()
    queued = []
    monkeypatch.setattr(tasks.password_reset_email, "delay", queued.append)
    with django_capture_on_commit_callbacks(execute=True) as callbacks:
        known = client.post(reverse("password_reset"), {"email": "Alice@Example.org"})
        unknown = client.post(reverse("password_reset"), {"email": "nobody@example.org"})
    assert known.status_code == unknown.status_code == 302
    assert len(callbacks) == 2 and queued == ["Alice@Example.org", "nobody@example.org"]
    assert mail.outbox == []  # the worker sends it, or nobody

    tasks.password_reset_email("nobody@example.org")
    assert mail.outbox == []
    tasks.password_reset_email("Alice@Example.org")
    (email,) = mail.outbox
    assert email.to == ["alice@example.org"] and "You log in as: alice" in email.body


def test_a_reset_request_that_is_not_an_email_address_says_so(client, by_email):
    response = client.post(reverse("password_reset"), {"email": "alice"})
    assert response.status_code == 400
    assert "That is not an email address: it looks like name@example.org." in response.text


def test_reset_requests_for_one_address_are_limited(client, alice, by_email, settings, worker):
    alice.email = "alice@example.org"
    alice.save()
    for _ in range(3):
        assert (
            client.post(reverse("password_reset"), {"email": "alice@example.org"}).status_code
            == 302
        )
    refused = client.post(reverse("password_reset"), {"email": "ALICE@example.org"})
    assert refused.status_code == 429
    assert 1 <= int(refused.headers["Retry-After"]) <= 3600  # the limit's window: an hour
    assert "Too many password reset requests for that email address for now" in refused.text
    assert len(mail.outbox) == 3


def test_without_email_the_page_says_to_ask_the_league_staff(client, alice, settings):
    settings.PITLANE_PASSWORD_RESET_BY_EMAIL = False
    alice.email = "alice@example.org"
    alice.save()
    page = client.get(reverse("password_reset")).text
    assert "This console sends no email" in page and "Ask your league staff" in page
    assert 'name="email"' not in page
    response = client.post(reverse("password_reset"), {"email": "alice@example.org"})
    assert response.status_code == 200 and "Ask your league staff" in response.text
    assert mail.outbox == []


def test_the_admin_user_page_tells_staff_how_to_set_a_forgotten_password(client, alice, stella):
    stella.is_superuser = True
    stella.save()
    client.force_login(stella)
    page = client.get(reverse("admin:auth_user_change", args=[alice.pk])).text
    assert "A racer who forgot their password" in page
    assert "Reset password" in page
    assert 'name="profile-0-racer_name"' in page and 'value="alice"' in page
    found = client.get(reverse("admin:auth_user_changelist"), {"q": "alice"}).text
    assert "1 result" in found
