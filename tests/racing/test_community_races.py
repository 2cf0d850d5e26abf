"""Community races: invitations, taking a racer out, and the form that sets a race up."""

import re
from datetime import datetime, timedelta
from zoneinfo import ZoneInfo

import pytest
from django.urls import reverse
from django.utils import timezone

from racing import services
from racing.forms import CommunityRaceForm
from racing.models import Event, Ranking, Submission
from tests.helpers.league import scored
from tests.helpers.models import ready_model
from tests.helpers.training import field_html, field_words, form_data
from tests.racing.conftest import race_form

pytestmark = pytest.mark.django_db


def invitation(event: Event) -> str:
    return reverse("racing:event-join", args=[event.invite_token])


def test_a_racer_taken_out_cannot_rejoin_with_the_same_invitation(
    client, community_race, alice, bob
):
    client.force_login(bob)
    client.post(invitation(community_race))
    client.force_login(alice)
    client.post(reverse("racing:community-race-remove", args=[community_race.slug, bob.pk]))

    client.force_login(bob)
    page = client.get(invitation(community_race))
    assert page.status_code == 403
    assert "alice took you out of Friday night" in page.text
    assert "ask alice to let you back in" in page.text
    assert "Join the race" not in page.text
    client.post(invitation(community_race))
    assert not community_race.participants.filter(pk=bob.pk).exists()
    assert client.get(community_race.get_absolute_url()).status_code == 404


def test_the_organiser_lets_a_racer_they_took_out_back_in(client, community_race, alice, bob):
    community_race.participants.add(bob)
    scored(community_race, bob, 10_000)
    client.force_login(alice)
    client.post(reverse("racing:community-race-remove", args=[community_race.slug, bob.pk]))
    manage = client.get(reverse("racing:community-race-manage", args=[community_race.slug]))
    assert "Taken out" in manage.text and "Let back in" in manage.text

    readmit = reverse("racing:community-race-readmit", args=[community_race.slug, bob.pk])
    client.post(readmit)
    assert community_race.participants.filter(pk=bob.pk).exists()
    assert not community_race.removed.exists()
    assert Ranking.objects.filter(event=community_race, racer=bob).exists()  # its runs rank again


def test_a_new_invitation_link_replaces_the_old_one(client, community_race, alice, bob):
    old = invitation(community_race)
    client.force_login(alice)
    client.post(reverse("racing:community-race-invitation-renew", args=[community_race.slug]))
    community_race.refresh_from_db()
    assert invitation(community_race) != old
    client.force_login(bob)
    assert client.get(old).status_code == 404
    client.post(invitation(community_race))
    assert community_race.participants.filter(pk=bob.pk).exists()


def test_only_the_organiser_readmits_or_renews(client, community_race, bob):
    client.force_login(bob)
    renew = reverse("racing:community-race-invitation-renew", args=[community_race.slug])
    assert client.post(renew).status_code == 404


def test_a_visitor_is_offered_to_sign_up_and_come_back_to_the_invitation(client, community_race):
    page = client.get(invitation(community_race))
    back = f"?next=/races/invite/{community_race.invite_token}/"
    assert f'href="{reverse("signup")}{back}"' in page.text
    assert f'href="{reverse("login")}{back}"' in page.text


def test_a_new_race_opens_now_and_closes_in_a_week_in_the_organisers_zone(client, alice, tracks):
    client.force_login(alice)
    client.cookies["pitlane_tz"] = "Asia/Tokyo"
    page = client.get(reverse("racing:community-race-create"))
    tokyo = ZoneInfo("Asia/Tokyo")

    def shown(name: str) -> datetime:
        value = re.search(rf'name="{name}" value="([^"]+)"', page.text)[1]
        return datetime.strptime(value, "%Y-%m-%dT%H:%M").replace(tzinfo=tokyo)

    assert abs(shown("opens_at") - timezone.now()) < timedelta(minutes=2)
    assert shown("closes_at") - shown("opens_at") == timedelta(days=7)
    assert re.search(r'name="track" value="[\w-]+" checked', page.text)  # a track chosen


def test_the_race_form_shows_track_pictures_and_only_the_race_types_fields(client, alice, tracks):
    client.force_login(alice)
    page = client.get(reverse("racing:community-race-create"))
    assert reverse("training:track-preview", args=["pitlane-oval"]) in page.text
    assert '<div data-race-fields="OBJECT_AVOIDANCE" hidden>' in page.text
    assert '<div data-race-fields="HEAD_TO_BOT" hidden>' in page.text


def test_an_object_avoidance_race_takes_its_boxes_from_the_form(client, alice, tracks):
    client.force_login(alice)
    form = race_form(race_type="OBJECT_AVOIDANCE", box_count=5, box_randomize="on")
    response = client.post(reverse("racing:community-race-create"), form)
    assert response.status_code == 302, response.context["form"].errors
    event = Event.objects.get(name="Friday night")
    assert event.boxes == {"count": 5, "randomize": True} and event.bots is None


def test_a_head_to_bot_race_without_its_bot_cars_says_so_and_keeps_them_shown(
    client, alice, tracks
):
    client.force_login(alice)
    form = race_form(race_type="HEAD_TO_BOT", bot_count="", bot_speed="1.5")
    response = client.post(reverse("racing:community-race-create"), form)
    assert response.context["form"].errors["bot_count"] == ["Say how many bot cars the race has."]
    assert '<div data-race-fields="HEAD_TO_BOT" >' in response.text
    assert 'value="1.5"' in response.text


def test_a_model_trains_under_the_limits_of_boxes_and_bot_cars_a_race_is_held_under(
    client, alice, tracks
):
    """One definition of a race's boxes and bot cars: the create-model page and a race's page
    show the same inputs, labels and help, and refuse a bot too fast in the same words."""
    client.force_login(alice)
    model_page = client.get(reverse("training:model-create")).text
    race_page = client.get(reverse("racing:community-race-create")).text
    for name in ("box_count", "box_randomize", "bot_count", "bot_speed", "bot_lane_changes"):
        assert field_html(model_page, name) == field_html(race_page, name)
        assert field_words(model_page, name) == field_words(race_page, name)
    assert 'value="0.2"' in field_html(race_page, "bot_speed")  # DeepRacer's default
    too_fast = {"race_type": "HEAD_TO_BOT", "bot_count": 2, "bot_speed": "6.5"}
    model = client.post(reverse("training:model-create"), form_data(**too_fast))
    race = client.post(reverse("racing:community-race-create"), race_form(**too_fast))
    refused = ["Bot car speed [m/s] is at most 6."]
    assert model.context["form"].errors["bot_speed"] == race.context["form"].errors["bot_speed"]
    assert race.context["form"].errors["bot_speed"] == refused


def test_the_same_race_form_sent_twice_creates_one_race(client, alice, tracks):
    client.force_login(alice)
    form = race_form()
    first = client.post(reverse("racing:community-race-create"), form)
    again = client.post(reverse("racing:community-race-create"), form, follow=True)
    race = Event.objects.get()
    assert first.url == reverse("racing:community-race-manage", args=[race.slug])
    assert again.redirect_chain[-1][0] == first.url
    assert "This form created Friday night already, so here it is: no second race." in again.text


def test_the_same_form_sent_again_with_other_settings_is_refused_and_keeps_them(
    client, alice, tracks
):
    """Back, change the laps, submit: neither the old race nor a second one, but words."""
    client.force_login(alice)
    form = race_form()
    client.post(reverse("racing:community-race-create"), form)
    changed = client.post(reverse("racing:community-race-create"), {**form, "laps_to_drive": 5})
    assert changed.status_code == 200
    assert (
        "This form already created Friday night; open the form again to organise another race."
        in changed.text
    )
    assert "a moment ago" not in changed.text
    assert changed.context["form"]["laps_to_drive"].value() == "5"
    assert Event.objects.get().laps_to_drive == 3


def test_the_same_race_sent_again_from_a_fresh_form_gives_back_the_race_just_made(
    client, alice, tracks
):
    """Back may fetch the form anew (a new token) while the browser keeps what was typed."""
    client.force_login(alice)
    client.post(reverse("racing:community-race-create"), race_form())
    again = client.post(reverse("racing:community-race-create"), race_form(), follow=True)
    race = Event.objects.get()
    assert again.redirect_chain[-1][0] == reverse("racing:community-race-manage", args=[race.slug])
    assert "You created Friday night with these settings a moment ago" in again.text
    assert "give it another name" in again.text

    client.post(reverse("racing:community-race-create"), race_form(name="Saturday"))
    client.post(reverse("racing:community-race-create"), race_form(laps_to_drive=5))
    client.post(
        reverse("racing:community-race-create"),
        race_form(race_type="HEAD_TO_BOT", bot_count=2, bot_speed="1.5"),
    )
    assert Event.objects.count() == 4


def test_a_race_form_without_its_token_asks_to_check_and_send_it_again(client, alice, tracks):
    client.force_login(alice)
    response = client.post(reverse("racing:community-race-create"), race_form(form_token=""))
    assert response.status_code == 200 and not Event.objects.exists()
    assert "This page was out of date: check the race below, then create it again." in (
        response.text
    )
    token = re.search(r'name="form_token" value="([\w-]+)"', response.text)[1]
    client.post(reverse("racing:community-race-create"), race_form(form_token=token))
    assert Event.objects.get().form_token == token


def test_the_organiser_deletes_a_race_nobody_has_entered_after_being_asked(
    client, community_race, alice
):
    client.force_login(alice)
    delete = reverse("racing:community-race-delete", args=[community_race.slug])
    assert (
        delete
        in client.get(reverse("racing:community-race-manage", args=[community_race.slug])).text
    )
    asked = client.get(delete)
    assert "Delete Friday night?" in asked.text and "Nobody has submitted to it yet" in asked.text
    assert Event.objects.filter(pk=community_race.pk).exists()  # asking deletes nothing
    done = client.post(delete, follow=True)
    assert done.redirect_chain[-1][0] == reverse("racing:race-list")
    assert "Friday night is deleted." in done.text
    assert not Event.objects.filter(pk=community_race.pk).exists()


def test_a_race_with_submissions_is_not_deleted_and_the_organiser_is_told_why(
    client, community_race, alice, bob
):
    community_race.participants.add(bob)
    scored(community_race, bob, 10_000)
    client.force_login(alice)
    delete = reverse("racing:community-race-delete", args=[community_race.slug])
    reason = "Friday night has 1 submission, so it stays"
    asked = client.get(delete)
    assert reason in asked.text and "Delete Friday night</button>" not in asked.text
    refused = client.post(delete, follow=True)
    assert reason in refused.text
    assert Event.objects.filter(pk=community_race.pk).exists()


def test_only_the_organiser_deletes_their_race(client, community_race, bob):
    community_race.participants.add(bob)
    client.force_login(bob)
    delete = reverse("racing:community-race-delete", args=[community_race.slug])
    assert client.get(delete).status_code == 404
    assert client.post(delete).status_code == 404
    assert Event.objects.filter(pk=community_race.pk).exists()


def test_two_requests_from_one_form_at_once_make_one_race(alice, tracks, monkeypatch):
    """A double click: both requests find no race from the form, one saves first."""
    form = CommunityRaceForm(race_form(), organiser=alice)
    assert form.is_valid(), form.errors
    token = form.cleaned_data["form_token"]
    first, created = services.community_race_create(
        organiser=alice, fields=form.fields_for_service(), form_token=token
    )
    looked = iter([None, first])  # the twin looks before the first saves, then after
    monkeypatch.setattr(services, "_race_from_form", lambda organiser, token: next(looked))
    monkeypatch.setattr(services, "_same_race_just_made", lambda *looked: None)
    second, again = services.community_race_create(
        organiser=alice, fields=form.fields_for_service(), form_token=token
    )
    assert (created, again, second) == (
        services.RaceMade.NEW,
        services.RaceMade.BY_THIS_FORM,
        first,
    )
    assert Event.objects.count() == 1


def test_a_submission_to_a_race_deleted_meanwhile_is_refused_in_words(community_race, alice, bob):
    community_race.participants.add(bob)
    model = ready_model(bob)
    services.community_race_delete(event=Event.objects.get(pk=community_race.pk))
    with pytest.raises(
        services.SubmissionRefused, match="Friday night was deleted by its organiser"
    ):
        services.submission_create(racer=bob, event=community_race, model=model)
    assert not Submission.objects.exists()


def test_deleting_a_race_and_submitting_to_it_lock_the_races_row(
    community_race, alice, bob, monkeypatch
):
    """Submitting holds the race's row, so a deletion that looked first waits, then finds the
    submission (and refuses); one that deletes first leaves the submission nothing to join."""
    locked = []
    lock = Event.objects.select_for_update
    monkeypatch.setattr(Event.objects, "select_for_update", lambda: locked.append(1) or lock())
    community_race.participants.add(bob)
    services.submission_create(racer=bob, event=community_race, model=ready_model(bob))
    assert locked == [1]
    with pytest.raises(services.RaceNotDeleted):
        services.community_race_delete(event=community_race)
    assert locked == [1, 1]
