"""Other racers know a racer by their racer name: a login name, a credential, never shows on
a page another racer or a visitor reads."""

import pytest
from django.contrib.auth.models import User
from django.template import engines
from django.urls import reverse

from accounts.models import Profile
from tests.helpers.league import event, scored

pytestmark = pytest.mark.django_db


@pytest.fixture
def renamed(alice, bob) -> None:
    Profile.objects.filter(user=alice).update(racer_name="Flash_A")
    Profile.objects.filter(user=bob).update(racer_name="Bolt_B")


def test_season_standings_show_racer_names_and_key_racers_by_account(
    client, alice, bob, renamed, tracks
):
    trial = event()
    scored(trial, alice, 9_000, 9_000, 9_000)
    scored(trial, bob, 10_000, 10_000, 10_000)
    page = client.get(reverse("racing:season-standings", args=[trial.season_id])).text
    assert "Flash_A" in page and "Bolt_B" in page
    assert "alice" not in page and "bob" not in page


def test_a_community_races_pages_name_its_organiser_and_racers_by_racer_name(
    client, community_race, alice, bob, renamed
):
    join = reverse("racing:event-join", args=[community_race.invite_token])
    client.force_login(bob)
    assert "Flash_A" in client.get(join).text and "alice" not in client.get(join).text
    client.post(join)
    for url in (community_race.get_absolute_url(), reverse("racing:race-list")):
        page = client.get(url).text
        assert "Flash_A" in page and "alice" not in page, url

    client.force_login(alice)
    manage = client.get(reverse("racing:community-race-manage", args=[community_race.slug]))
    assert 'aria-label="Remove Bolt_B"' in manage.text and "bob" not in manage.text
    removed = client.post(
        reverse("racing:community-race-remove", args=[community_race.slug, bob.pk]), follow=True
    )
    assert "Bolt_B is out of Friday night." in removed.text and "bob" not in removed.text

    client.force_login(bob)
    refused = client.get(join).text
    assert "Flash_A took you out of Friday night" in refused and "alice" not in refused


def test_an_account_without_a_profile_shows_as_a_numbered_racer_never_its_login_name(alice):
    Profile.objects.filter(user=alice).delete()
    alice = User.objects.get(pk=alice.pk)
    shown = engines["django"].from_string("{% load racers %}{% racer r %}|{{ r|racer_name }}")
    said = shown.render({"r": alice})
    assert f"Racer #{alice.pk}" in said and "alice" not in said
    assert not Profile.objects.filter(user=alice).exists()
