"""Race day through the API, with the live race page's rules: racers join and leave the queue;
the facilitator (staff with a staff token, or a community race's organiser) opens the session,
reorders the queue and launches a turn; nobody else may, and a winner is shown only once
someone is ranked."""

from __future__ import annotations

import pytest

from racing.models import LiveEntry
from tests.helpers.accounts import api_token
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model

pytestmark = pytest.mark.django_db
JSON = "application/json"


def test_racers_queue_the_facilitator_reorders_and_launches_and_others_may_not(
    alice, bob, stella, tracks, client
):
    race = event("Live cup", laps_required=1)
    live = f"/api/v1/events/{race.slug}/live"
    staff, hers, his = (
        api_token(stella, "read", "race", "admin"),
        api_token(alice, "read", "race"),
        api_token(bob, "read", "race"),
    )
    mine = ready_model(alice, name="hers")
    closed = client.post(f"{live}/queue", {"model": mine.pk}, JSON, **hers)
    assert closed.status_code == 409 and closed.json()["code"] == "not_open"
    assert client.post(live, {}, JSON, **api_token(stella, "race")).status_code == 403  # no admin
    assert client.post(live, {}, JSON, **hers).status_code == 404  # not hers to run
    opened = client.post(live, {"max_speed": 1.2}, JSON, **staff)
    assert opened.status_code == 200 and opened.json()["open"] is True

    joined = client.post(f"{live}/queue", {"model": mine.pk, "speed": 1.2}, JSON, **hers)
    assert joined.status_code == 201 and joined.json()["place"] == 1
    his_model = ready_model(bob)
    too_fast = client.post(f"{live}/queue", {"model": his_model.pk, "speed": 1.5}, JSON, **his)
    assert too_fast.status_code == 409 and "from 0.5 to 1.2" in too_fast.json()["message"]
    not_his = client.post(f"{live}/queue", {"model": mine.pk}, JSON, **his)
    assert not_his.status_code == 404
    his_place = client.post(f"{live}/queue", {"model": his_model.pk}, JSON, **his)
    assert his_place.status_code == 201 and his_place.json()["place"] == 2

    entry = his_place.json()["id"]
    assert client.post(f"{live}/queue/{entry}/up", **hers).status_code == 404  # racers may not
    moved = client.post(f"{live}/queue/{entry}/up", **staff)
    assert [row["racer"] for row in moved.json()["entries"]] == ["bob", "alice"]
    assert client.delete(f"{live}/queue/{entry}", **hers).status_code == 404  # not her place
    left = client.delete(f"{live}/queue/{joined.json()['id']}", **hers)
    assert [row["racer"] for row in left.json()["entries"]] == ["bob"]

    launched = client.post(f"{live}/launch", **staff)
    assert launched.status_code == 200 and [car["racer"] for car in launched.json()["cars"]] == [
        "bob"
    ]
    assert LiveEntry.objects.get(pk=entry).status == LiveEntry.Status.DRIVING
    again = client.post(f"{live}/launch", **staff)
    assert again.status_code == 409 and "A turn is driving" in again.json()["message"]
    assert client.get(live, **his).json()["cars"][0]["model_name"] == "straight-ahead"

    winner = f"/api/v1/events/{race.slug}/winner"
    assert client.post(winner, {}, JSON, **staff).status_code == 409  # nobody ranked yet
    scored(race, alice, 7_500, model_name="quick")
    shown = client.post(winner, {}, JSON, **staff)
    assert shown.status_code == 200 and shown.json()["winner"]["racer"] == "alice"
    assert client.post(winner, {}, JSON, **his).status_code == 404
