"""The league in the API: events as the pages show them to each racer, leaderboards by racer
name, a submission under the submit page's rules, and a racer's own runs."""

from __future__ import annotations

from accounts.models import Profile
from racing.models import Submission
from tests.helpers.accounts import api_token
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from training.models import RLModel, TrainingJob


def test_a_leaderboard_ranks_by_racer_name_and_a_private_race_is_its_racers_alone(
    alice, bob, stella, tracks, client
):
    Profile.objects.filter(user=alice).update(racer_name="FastAlice")  # not her login name
    race = event("Time trial", laps_required=1)
    scored(race, alice, 9_000, model_name="quick")
    scored(race, bob, 7_500, model_name="quicker")
    private = event("Club night", public=False, organiser=alice)
    token = api_token(bob, "read")
    slugs = [e["slug"] for e in client.get("/api/v1/events", **token).json()]
    assert slugs == ["time-trial"]
    assert client.get(f"/api/v1/events/{private.slug}", **token).status_code == 404
    assert private.slug in [
        e["slug"] for e in client.get("/api/v1/events", **api_token(alice, "read")).json()
    ]

    board = client.get(f"/api/v1/events/{race.slug}/leaderboard", **token).json()
    assert board["count"] == 2 and board["pages"] == 1
    places = [(r["position"], r["racer"], r["model_name"], r["gap_ms"]) for r in board["items"]]
    assert places == [(1, "bob", "quicker", 0), (2, "FastAlice", "quick", 1_500)]


def test_a_submission_is_raced_under_the_submit_pages_rules(alice, bob, tracks, client):
    race = event("Time trial", laps_required=1)
    model = ready_model(alice)
    racing = api_token(alice, "read", "race")
    url = f"/api/v1/events/{race.slug}/submissions"
    reader = client.post(
        url, {"model": model.pk}, content_type="application/json", **api_token(alice, "read")
    )
    assert reader.status_code == 403
    others = client.post(
        url, {"model": model.pk}, content_type="application/json", **api_token(bob, "race")
    )
    assert others.status_code == 404  # not bob's model

    entered = client.post(url, {"model": model.pk}, content_type="application/json", **racing)
    assert entered.status_code == 201
    run = entered.json()
    assert (run["event"], run["model"], run["status"]) == (race.slug, model.pk, "QUEUED")
    model.refresh_from_db()
    assert model.status == RLModel.Status.SUBMITTING
    again = client.post(url, {"model": model.pk}, content_type="application/json", **racing)
    assert again.status_code == 409 and again.json()["code"] == "refused"
    assert Submission.objects.count() == 1

    mine = client.get("/api/v1/submissions", **racing).json()
    assert [r["id"] for r in mine] == [run["id"]]
    assert client.get(f"/api/v1/submissions/{run['id']}", **racing).json()["laps"] == []
    assert (
        client.get(f"/api/v1/submissions/{run['id']}", **api_token(bob, "read")).status_code == 404
    )


def test_seasons_and_their_standings_score_as_the_page_does(alice, bob, tracks, client):
    race = event("Time trial", laps_required=1)
    scored(race, alice, 9_000)
    scored(race, bob, 7_500)
    event("Club night", public=False, organiser=alice)  # private: in no season's list
    token = api_token(bob, "read")
    seasons = client.get("/api/v1/seasons", **token).json()
    assert [(s["name"], s["events"]) for s in seasons] == [("Test season", ["time-trial"])]
    table = client.get("/api/v1/seasons/Test%20season/standings?division=OPEN", **token).json()
    assert [(s["racer"], s["points"], s["finishes"]) for s in table["standings"]] == [
        ("bob", 25, [1]),
        ("alice", 18, [2]),
    ]
    assert client.get("/api/v1/seasons/Nope/standings", **token).status_code == 404
    assert (
        client.get("/api/v1/seasons/Test%20season/standings?division=gold", **token).status_code
        == 400
    )


def test_staff_read_the_systems_health_and_the_training_queue_and_racers_may_not(
    alice, stella, tracks, client
):
    waiting = [ready_model(alice, name=f"waiting-{n}") for n in (1, 2)]
    jobs = [TrainingJob.objects.create(model=model) for model in waiting]
    answer = client.get("/api/v1/system", **api_token(stella, "read", "admin"))
    assert answer.status_code == 200
    body = answer.json()
    assert (
        set(body["checks"]) == {"database", "redis", "workers"} and body["checks"]["database"]["ok"]
    )
    assert [(j["job"], j["queue_position"], j["racer"]) for j in body["queue"]] == [
        (jobs[0].pk, 1, "alice"),
        (jobs[1].pk, 2, "alice"),
    ]
    assert client.get("/api/v1/system", **api_token(stella, "read")).status_code == 403
    client.force_login(alice)  # a racer's session has every scope but admin
    assert client.get("/api/v1/system").status_code == 403
