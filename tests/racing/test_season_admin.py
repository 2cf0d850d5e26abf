"""League staff add a season with its events in one admin form."""

import pytest
from django.contrib.auth.models import User
from django.urls import reverse

from racing.models import Event, Season
from tests.helpers.accounts import PASSWORD
from tests.helpers.league import race_staff_group
from training.models import Track

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


@pytest.fixture
def race_staff(db) -> User:
    user = User.objects.create_user("rita", password=PASSWORD, is_staff=True)
    user.groups.add(race_staff_group())
    return user


def season_form(**event) -> dict:
    """The add-season form with one inline event, as the admin page posts it."""
    prefix = "events-0-"
    fields = {
        "name": "Summer Cup",
        "slug": "summer-cup-july",
        "track": Track.objects.get(name="pitlane-oval").pk,
        "race_type": "TIME_TRIAL",
        "division": "OPEN",
        "opens_at": "2026-07-01T00:00",
        "closes_at": "2026-07-31T00:00",
        **event,
    }
    return {
        "name": "Summer 2026",
        "year": 2026,
        "starts_on": "2026-06-01",
        "ends_on": "2026-08-31",
        "events-TOTAL_FORMS": 1,
        "events-INITIAL_FORMS": 0,
        "events-MIN_NUM_FORMS": 0,
        "events-MAX_NUM_FORMS": 1000,
        **{prefix + name: value for name, value in fields.items()},
    }


def test_staff_add_a_season_with_an_event_in_one_form(client, race_staff):
    client.force_login(race_staff)
    response = client.post(reverse("admin:racing_season_add"), season_form())
    assert response.status_code == 302, response.context["inline_admin_formsets"][0].formset.errors
    event = Event.objects.get(slug="summer-cup-july")
    assert event.season == Season.objects.get(name="Summer 2026")


def test_an_event_outside_its_season_is_refused_with_the_season_dates(client, race_staff):
    client.force_login(race_staff)
    form = season_form(opens_at="2026-05-20T00:00", closes_at="2026-09-02T00:00")
    response = client.post(reverse("admin:racing_season_add"), form)
    assert response.status_code == 200
    errors = response.context["inline_admin_formsets"][0].formset.errors[0]
    days = "Summer 2026 runs from 1 June 2026 to 31 August 2026"
    assert errors["opens_at"] == [f"{days}: open the event within those days."]
    assert errors["closes_at"] == [f"{days}: close the event by the end of its last day."]
    assert f"{days}: open the event within those days." in response.text
    assert not Season.objects.exists()


def test_an_event_may_close_at_midnight_after_the_last_day(client, race_staff):
    client.force_login(race_staff)
    form = season_form(opens_at="2026-06-01T00:00", closes_at="2026-09-01T00:00")
    assert client.post(reverse("admin:racing_season_add"), form).status_code == 302


def event_form(**fields) -> dict:
    """The add-event form, as the admin page posts it."""
    return {
        "season": Season.objects.create(
            name="Summer 2026", year=2026, starts_on="2026-06-01", ends_on="2026-08-31"
        ).pk,
        "name": "Boxes in July",
        "slug": "boxes-in-july",
        "division": "PRO",
        "track": Track.objects.get(name="pitlane-oval").pk,
        "direction": "counterclockwise",
        "race_type": "OBJECT_AVOIDANCE",
        "box_count": 4,
        "bot_speed": 1.0,
        "bot_count": 3,
        "opens_at_0": "2026-07-01",
        "opens_at_1": "00:00:00",
        "closes_at_0": "2026-07-31",
        "closes_at_1": "00:00:00",
        "ranking_method": "FIRST_CONSECUTIVE",
        "laps_required": 3,
        "laps_to_drive": 3,
        "off_track_penalty_s": 2,
        "crash_penalty_s": 5,
        "submissions_per_racer": 10,
        "public": "on",
        **fields,
    }


def test_staff_set_boxes_and_bots_as_fields_not_json(client, race_staff):
    client.force_login(race_staff)
    page = client.get(reverse("admin:racing_event_add"))
    assert 'name="box_count"' in page.text and 'name="boxes"' not in page.text
    response = client.post(reverse("admin:racing_event_add"), event_form(box_randomize="on"))
    assert response.status_code == 302, response.context["adminform"].form.errors
    event = Event.objects.get(slug="boxes-in-july")
    assert event.boxes == {"count": 4, "randomize": True} and event.bots is None

    change = client.get(reverse("admin:racing_event_change", args=[event.pk]))
    assert 'name="box_count" value="4"' in change.text


def test_a_head_to_bot_event_without_its_bots_says_so_on_the_field(client, race_staff):
    client.force_login(race_staff)
    form = event_form(race_type="HEAD_TO_BOT", bot_count="", bot_speed="9")
    response = client.post(reverse("admin:racing_event_add"), form)
    errors = response.context["adminform"].form.errors
    assert errors["bot_count"] == ["Say how many bot cars the race has."]
    assert errors["bot_speed"] == ["Bot car speed [m/s] is at most 6."]
    assert not Event.objects.exists()


def test_an_error_on_a_field_the_row_does_not_show_is_said_in_the_row(client, race_staff):
    Track.objects.filter(name="pitlane-oval").update(counterclockwise=False)
    client.force_login(race_staff)
    response = client.post(reverse("admin:racing_season_add"), season_form())
    assert response.status_code == 200
    row = response.context["inline_admin_formsets"][0].formset.forms[0]
    assert row.non_field_errors() == ["Direction: Pitlane Oval cannot be driven counter-clockwise."]
    assert "Direction: Pitlane Oval cannot be driven counter-clockwise." in response.text


def test_an_events_own_page_refuses_dates_outside_its_season(client, race_staff):
    client.force_login(race_staff)
    response = client.post(reverse("admin:racing_event_add"), event_form(closes_at_0="2026-10-01"))
    errors = response.context["adminform"].form.errors
    days = "Summer 2026 runs from 1 June 2026 to 31 August 2026"
    assert errors == {"closes_at": [f"{days}: close the event by the end of its last day."]}
