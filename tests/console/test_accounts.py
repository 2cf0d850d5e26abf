import pytest
from django.contrib.auth.models import User
from django.urls import reverse

from tests.helpers.accounts import PASSWORD

pytestmark = pytest.mark.django_db


def test_a_new_racer_signs_up_and_is_logged_in(client):
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": PASSWORD},
        follow=True,
    )
    assert response.redirect_chain == [(reverse("home"), 302)]
    assert response.context["user"].username == "carol"
    assert User.objects.filter(username="carol").exists()


def test_a_new_racer_is_greeted_once_and_not_welcomed_back(client):
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": PASSWORD},
        follow=True,
    )
    assert response.text.count("Welcome") == 1
    assert "<h1>Welcome to Pitlane, carol!</h1>" in response.text
    assert "Welcome back, carol" in client.get(reverse("home")).text  # the next visit


def test_sign_up_takes_the_racer_back_where_they_were_going(client):
    invitation = "/races/invite/some-token/"
    form = client.get(reverse("signup"), {"next": invitation})
    assert f'<input type="hidden" name="next" value="{invitation}">' in form.text
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": PASSWORD, "next": invitation},
    )
    assert response.status_code == 302 and response.url == invitation
    assert client.session.get("_auth_user_id")


def test_a_racer_who_signs_up_on_the_way_to_a_page_is_greeted_there_once(client):
    races = reverse("racing:race-list")
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": PASSWORD, "next": races},
        follow=True,
    )
    assert response.redirect_chain == [(races, 302)]
    assert "Welcome to Pitlane, carol!" in response.text
    assert response.text.count("Welcome") == 1


@pytest.mark.parametrize("elsewhere", ["https://evil.example/", "//evil.example/", "javascript:x"])
def test_sign_up_never_sends_a_racer_off_the_site(client, elsewhere):
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": PASSWORD, "next": elsewhere},
    )
    assert response.status_code == 302 and response.url == reverse("home")


def test_a_sign_up_that_fails_keeps_where_the_racer_was_going(client):
    response = client.post(
        reverse("signup"),
        {"username": "carol", "password1": PASSWORD, "password2": "other", "next": "/races/"},
    )
    assert response.status_code == 400
    assert '<input type="hidden" name="next" value="/races/">' in response.text


def test_the_log_in_page_sends_new_racers_to_sign_up_with_where_they_were_going(client):
    page = client.get(reverse("login"), {"next": "/races/invite/some-token/"})
    signup = reverse("signup")
    assert f'href="{signup}?next=/races/invite/some-token/"' in page.text


def test_sign_up_refuses_a_login_name_that_is_taken_and_keeps_what_was_typed(client, alice):
    response = client.post(
        reverse("signup"), {"username": "ALICE", "password1": PASSWORD, "password2": PASSWORD}
    )
    assert response.status_code == 400
    assert "Another racer already logs in with that login name. Choose another." in response.text
    assert 'value="ALICE"' in response.text


def test_sign_up_asks_for_a_login_name_and_says_the_racer_name_starts_from_it(client):
    page = client.get(reverse("signup")).text
    assert '<label for="id_username">Login name</label>' in page
    assert "racer name, which starts as this name" in page
    assert "can be changed on your profile" in page


def test_a_renamed_racer_logs_in_with_the_login_name_the_page_asks_for(client, alice):
    alice.profile.racer_name = "zoom_z"
    alice.profile.save()
    page = client.get(reverse("login")).text
    assert '<label for="id_username">Login name</label>' in page
    assert "Racer name" not in page
    response = client.post(
        reverse("login"), {"username": "alice", "password": PASSWORD}, follow=True
    )
    assert response.context["user"] == alice


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
    assert "That login name and password do not match" in response.text
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
