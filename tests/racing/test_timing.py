"""Physical events (racing.timing): real cars timed at the track, scored by the event's rules
into the same leaderboard, from the timekeeper's keys or a timing device's posts."""

from __future__ import annotations

import json

import pytest
from django.urls import reverse

from racing import timing
from racing.models import Ranking, RankingMethod, Submission
from tests.helpers.league import DAY, event

pytestmark = pytest.mark.django_db

CROSSING = timing.Signal("crossing")


def a_run(physical_event, racer, staff):
    return timing.physical_run_start(
        event=physical_event, racer=racer, model_name="sim2real-v3", car="7", timekeeper=staff
    )


def drive(run, *signals):
    """Send signals in order: a number is a crossing at that clock reading [ms]."""
    for signal in signals:
        kind = (
            timing.Signal("crossing", signal) if isinstance(signal, int) else timing.Signal(signal)
        )
        run = timing.run_signal(run=run, signal=kind)
    return run


@pytest.mark.parametrize(
    ("method", "score_ms"),
    [
        # laps 10.000, 11.000 (9 s and an off-track's 2 s), 13.500 with 2 off-tracks (over the
        # event's 1: not counted), 8.000, 7.000; runs of 2 counted laps: laps 1-2 and 4-5
        (RankingMethod.FIRST_CONSECUTIVE, 10_500),
        (RankingMethod.BEST_CONSECUTIVE, 7_500),
        (RankingMethod.BEST_LAP, 7_000),
        (RankingMethod.TOTAL_TIME, 21_000),
    ],
)
def test_a_physical_run_is_scored_by_each_ranking_method_into_the_leaderboard(
    tracks, alice, stella, method, score_ms
):
    race = event(
        physical=True,
        ranking_method=method,
        laps_required=2,
        laps_to_drive=5,
        max_off_tracks_per_lap=1,
        off_track_penalty_s=2.0,
    )
    run = a_run(race, alice, stella)
    run = drive(
        run, 5_000, 15_000, "off_track", 24_000, "reset", "off_track", 33_500, 41_500, 48_500
    )
    laps = list(run.submission.laps.order_by("number"))
    assert [(lap.time_ms, lap.penalty_ms, lap.counted) for lap in laps] == [
        (10_000, 0, True),
        (11_000, 2_000, True),
        (13_500, 4_000, False),
        (8_000, 0, True),
        (7_000, 0, True),
    ]
    assert (laps[2].off_tracks, laps[2].resets) == (2, 1)

    timing.run_signal(run=run, signal=timing.Signal("finish"))
    submission = Submission.objects.get(pk=run.submission_id)
    assert submission.status == Submission.Status.COMPLETED and submission.physical
    assert submission.score_ms == score_ms and submission.qualified
    ranking = Ranking.objects.get(event=race, racer=alice)
    assert ranking.score_ms == score_ms and ranking.submission.physical
    assert alice.notifications.filter(text__contains=race.name).exists()


def test_undo_takes_back_the_last_crossing_and_its_off_tracks(tracks, alice, stella):
    run = a_run(event(physical=True), alice, stella)
    with pytest.raises(timing.TimingRefused, match="not crossed the line"):
        drive(run, "undo")
    run = drive(run, 1_000, "undo")  # the first crossing undone: the clock stops again
    assert run.line_crossed_ms is None
    run = drive(run, 2_000, "off_track", 12_000, 12_400 + 1_000)  # pressed twice, a second late
    assert run.submission.laps.count() == 2
    run = drive(run, "undo")
    assert run.submission.laps.count() == 1
    assert (run.line_crossed_ms, run.off_tracks) == (12_000, 0)
    run = drive(run, "undo")  # the lap with its off-track: that off-track is on the lap on track
    assert (run.line_crossed_ms, run.off_tracks) == (2_000, 1)
    with pytest.raises(timing.TimingRefused, match="the same crossing twice"):
        drive(run, 2_500)


def test_one_car_at_a_time_on_a_physical_event_that_is_open(tracks, alice, bob, stella):
    race = event(physical=True)
    run = a_run(race, alice, stella)
    with pytest.raises(timing.TimingRefused, match="still on the track"):
        a_run(race, bob, stella)
    drive(run, "finish")
    a_run(race, bob, stella)
    with pytest.raises(timing.TimingRefused, match="not raced by real cars"):
        a_run(event("Virtual"), bob, stella)
    with pytest.raises(timing.TimingRefused, match="has closed"):
        a_run(event("Over", physical=True, opens=-2 * DAY, closes=-DAY), bob, stella)


def device_post(client, race, body, token="") -> tuple[int, dict]:
    response = client.post(
        reverse("racing:timing-device", args=[race.slug]),
        data=body,
        content_type="application/json",
        headers={"Authorization": f"Bearer {token}"},
    )
    return response.status_code, response.json()


def test_a_timing_device_needs_the_events_token(client, tracks, alice, stella):
    race = event(physical=True)
    token = timing.timing_token_renew(event=race)
    crossing = json.dumps({"signal": "crossing", "at_ms": 50_000})

    assert device_post(client, race, crossing)[0] == 401  # no token
    assert device_post(client, race, crossing, token + "x")[0] == 401
    assert device_post(client, race, crossing, token) == (
        409,
        {"error": "No car is on the track: start a run first."},
    )
    a_run(race, alice, stella)
    status, state = device_post(client, race, crossing, token)
    assert status == 200 and state["lap_started_ms"] is not None and state["laps"] == []
    status, state = device_post(
        client, race, json.dumps({"signal": "crossing", "at_ms": 61_250}), token
    )
    assert status == 200 and [lap["time_ms"] for lap in state["laps"]] == [11_250]
    assert device_post(client, race, "not json", token)[0] == 400
    assert (
        device_post(client, race, json.dumps({"signal": "crossing", "at_ms": "soon"}), token)[0]
        == 400
    )
    assert device_post(client, race, json.dumps({"signal": "lap"}), token)[0] == 409
    # a new token: the old one stops working
    assert device_post(client, race, crossing, timing.timing_token_renew(event=race))[0] == 409
    assert device_post(client, race, crossing, token)[0] == 401
    virtual = event("Virtual")
    assert device_post(client, virtual, crossing, token)[0] == 404


def test_only_staff_and_the_organiser_keep_time_and_racers_cannot_submit_models(
    client, tracks, alice, stella
):
    from racing import selectors

    race = event(physical=True)
    page = reverse("racing:timekeeper", args=[race.slug])
    client.force_login(alice)
    assert client.get(page).status_code == 404
    assert "real cars" in selectors.submission_refusal(racer=alice, event=race, model=None)
    assert race not in selectors.events_open_to(racer=alice)
    client.force_login(stella)
    assert "Put the car on the track" in client.get(page).text
    response = client.post(page, {"racer": "nobody", "model_name": "m", "car": "1"})
    assert "No racer goes by the name nobody here" in response.text
