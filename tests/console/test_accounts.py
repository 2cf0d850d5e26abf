import pytest
from django.contrib.auth.models import User
from django.urls import reverse

from tests.conftest import PASSWORD

pytestmark = pytest.mark.django_db


def test_a_new_racer_signs_up_and_is_logged_in(client):
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": PASSWORD},
        follow=True,
    )
    assert response.redirect_chain == [(reverse("home"), 302)]
    assert response.context["user"].username == "carol"
    assert "Welcome to Pitlane, carol!" in response.text
    assert User.objects.filter(username="carol").exists()


def test_sign_up_refuses_a_racer_name_that_is_taken_and_keeps_what_was_typed(client, alice):
    response = client.post(
        reverse("signup"), {"username": "alice", "password1": PASSWORD, "password2": PASSWORD}
    )
    assert response.status_code == 400
    assert "A user with that username already exists." in response.text
    assert 'value="alice"' in response.text


def test_sign_up_says_when_the_passwords_differ(client):
    response = client.post(
        reverse("signup"), {"username": "carol", "password1": PASSWORD, "password2": "other"}
    )
    assert response.status_code == 400
    assert "The two password fields didn\u2019t match." in response.text
    assert not User.objects.filter(username="carol").exists()


def test_a_racer_logs_in_and_out(client, alice):
    response = client.post(
        reverse("login"), {"username": "alice", "password": PASSWORD}, follow=True
    )
    assert response.context["user"] == alice
    response = client.post(reverse("logout"), follow=True)
    assert not response.context["user"].is_authenticated


def test_a_wrong_password_gets_a_clear_message(client, alice):
    response = client.post(reverse("login"), {"username": "alice", "password": "wrong"})
    assert response.status_code == 200
    assert "That racer name and password do not match" in response.text
    assert not response.context["user"].is_authenticated


def test_a_racer_changes_their_password(client, alice):
    client.force_login(alice)
    response = client.post(
        reverse("password_change"),
        {
            "old_password": PASSWORD,
            "new_password1": "a-brand-new-pass-phrase",
            "new_password2": "a-brand-new-pass-phrase",
        },
        follow=True,
    )
    assert "Password changed" in response.text
    alice.refresh_from_db()
    assert alice.check_password("a-brand-new-pass-phrase")


def test_changing_the_password_needs_the_old_one(client, alice):
    client.force_login(alice)
    response = client.post(
        reverse("password_change"),
        {
            "old_password": "wrong",
            "new_password1": "x-y-z-1-2-3-4",
            "new_password2": "x-y-z-1-2-3-4",
        },
    )
    assert "Your old password was entered incorrectly" in response.text
    alice.refresh_from_db()
    assert alice.check_password(PASSWORD)


def test_pages_for_racers_send_visitors_to_log_in(client):
    response = client.get(reverse("training:model-list"))
    assert response.status_code == 302
    assert response["Location"].startswith(reverse("login"))
