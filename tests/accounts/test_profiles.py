import pytest
from django.contrib.auth.models import User
from django.urls import reverse

from accounts.models import Profile
from accounts.services import profile_ensure
from tests.helpers.accounts import PASSWORD
from tests.helpers.league import event, scored

pytestmark = pytest.mark.django_db

RULE = "A racer name is 2 to 64 letters, digits, hyphens (-) and underscores (_), no spaces"


def profile_form(**fields) -> dict:
    return {
        "racer_name": "Alice_R",
        "country": "NZ",
        "avatar_colour": "purple",
        "email": "",
        **fields,
    }


def test_every_new_account_gets_a_profile_named_after_it():
    racer = User.objects.create_user(username="carol", password="x")
    assert racer.profile.racer_name == "carol"


def test_a_username_a_racer_name_cannot_hold_becomes_one_it_can_and_a_free_one(alice):
    Profile.objects.filter(user=alice).update(racer_name="dana-example-org")
    dana = User.objects.create_user(username="dana@example.org", password="x")
    assert dana.profile.racer_name == "dana-example-org-2"
    assert User.objects.create_user(username="e", password="x").profile.racer_name == "e-"


def test_an_account_from_before_profiles_gets_one_on_first_sight(alice):
    Profile.objects.filter(user=alice).delete()
    assert profile_ensure(user=User.objects.get(pk=alice.pk)).racer_name == "alice"


def test_the_user_menu_opens_the_racer_profile(client, alice):
    client.force_login(alice)
    home = client.get(reverse("home")).text
    assert f'<a href="{reverse("accounts:profile")}" title="Your racer profile">alice</a>' in home


def test_a_racer_saves_their_name_country_avatar_and_email(client, alice):
    client.force_login(alice)
    response = client.post(
        reverse("accounts:profile"),
        profile_form(email="alice@example.org", password=PASSWORD),
        follow=True,
    )
    assert "Your profile is saved." in response.text  # the suite's console sends no email
    alice.refresh_from_db()
    profile = alice.profile
    assert (profile.racer_name, profile.country, profile.avatar_colour) == (
        "Alice_R",
        "NZ",
        "purple",
    )
    assert alice.email == "alice@example.org"
    assert 'href="/accounts/password/">Change your password</a>' in response.text


@pytest.mark.parametrize(
    ("fields", "error"),
    [
        ({"racer_name": ""}, "Choose a racer name for the leaderboards."),
        ({"racer_name": "a"}, RULE),
        ({"racer_name": "fast car"}, RULE),
        ({"racer_name": "x" * 65}, "that one has 65."),
        ({"racer_name": "BOB"}, "Another racer already races as BOB"),
        ({"country": "XX"}, "Choose your country from the list, or Not shown."),
        ({"avatar_colour": "gold"}, "Choose one of the colours shown."),
        ({"email": "alice.example.org"}, "That is not an email address"),
    ],
)  # fmt: skip
def test_a_profile_with_bad_input_gets_a_clear_error_and_keeps_what_was_typed(
    client, alice, bob, fields, error
):
    client.force_login(alice)
    response = client.post(reverse("accounts:profile"), profile_form(**fields))
    assert response.status_code == 400
    assert error in response.text
    assert response.text.count('class="field-error"') == 1
    alice.profile.refresh_from_db()
    assert alice.profile.racer_name == "alice"  # nothing saved


def test_a_racer_may_keep_their_own_name_in_other_capitals(client, alice):
    client.force_login(alice)
    response = client.post(reverse("accounts:profile"), profile_form(racer_name="ALICE"))
    assert response.status_code == 302
    assert Profile.objects.get(user=alice).racer_name == "ALICE"


def test_the_profile_page_says_notifications_go_to_the_email_address_too(client, alice, settings):
    settings.PITLANE_PASSWORD_RESET_BY_EMAIL = settings.PITLANE_EMAIL_NOTIFICATIONS = True
    client.force_login(alice)
    page = client.get(reverse("accounts:profile")).text
    assert "Your password reset links and your notifications" in page
    assert "Only for password reset links" not in page and "flag" not in page
    assert '"Forgot your password?" on the login page emails a reset link' in page


def test_the_header_names_the_racer_by_their_racer_name_not_their_login_name(client, alice):
    Profile.objects.filter(user=alice).update(racer_name="VeraFast")
    client.force_login(alice)
    for page in (reverse("home"), reverse("accounts:profile"), reverse("racing:race-list")):
        header = client.get(page).text.split('<main id="main"', 1)[0]
        assert '<a href="/accounts/profile/" title="Your racer profile"' in header
        assert ">VeraFast</a>" in header
        assert "alice" not in header
    assert "Welcome back, VeraFast" in client.get(reverse("home")).text


def test_without_a_mail_server_the_profile_promises_no_email_and_says_who_resets_a_password(
    client, alice, settings
):
    settings.PITLANE_PASSWORD_RESET_BY_EMAIL = settings.PITLANE_EMAIL_NOTIFICATIONS = False
    client.force_login(alice)
    page = client.get(reverse("accounts:profile")).text
    assert "This console sends no email (its operator has set up no mail server)" in page
    assert "reset links" not in page and "notifications (" not in page
    assert "If you forget your password, ask your league staff" in page


def test_the_profile_page_is_for_racers_who_are_logged_in(client):
    response = client.get(reverse("accounts:profile"))
    assert response.status_code == 302 and response.url.startswith(reverse("login"))


def test_the_leaderboard_shows_racer_names_countries_and_avatars(client, alice, bob, tracks):
    Profile.objects.filter(user=alice).update(
        racer_name="Speedy-A", country="NZ", avatar_colour="red"
    )
    trial = event("Time trial")
    scored(trial, alice, 10_000, 10_000, 10_000)
    scored(trial, bob, 11_000, 11_000, 11_000)
    client.force_login(bob)
    response = client.get(trial.get_absolute_url())
    page = response.text
    assert '<span class="avatar avatar-red" aria-hidden="true">S</span>' in page
    assert '<span class="racer-name">Speedy-A</span>' in page
    assert '<abbr class="racer-country" title="New Zealand">NZ</abbr>' in page
    assert '<span class="racer-name">bob</span>' in page
    assert ">alice<" not in page  # her login name is not shown


def test_the_help_page_says_where_a_racer_chooses_how_leaderboards_show_them(client):
    page = client.get(reverse("help")).text
    assert f'<a href="{reverse("accounts:profile")}">racer profile</a>' in page


def test_wrong_current_passwords_on_the_profile_end_in_a_wait_even_for_the_right_one(
    client, alice, settings
):
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "profile-password": "2/15m"}
    client.force_login(alice)
    url = reverse("accounts:profile")
    asked = profile_form(email="new@example.org")
    assert client.post(url, {**asked, "password": PASSWORD}).status_code == 302  # not counted
    for _ in range(2):
        assert (
            client.post(url, {**asked, "email": "x@example.org", "password": "guess"}).status_code
            == 400
        )
    response = client.post(url, {**asked, "email": "y@example.org", "password": PASSWORD})
    assert response.status_code == 429
    assert 1 <= int(response.headers["Retry-After"]) <= 15 * 60
    assert "Too many wrong current passwords on your profile for now: try again in" in response.text
    assert User.objects.get(pk=alice.pk).email == "new@example.org"
