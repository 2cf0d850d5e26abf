"""Physical events (racing.timing): real cars timed at the track, scored by the event's rules
into the same leaderboard, from the timekeeper's keys or a timing device's posts."""

from __future__ import annotations

import json
from datetime import timedelta

import pytest
from django.urls import reverse
from django.utils import timezone

from accounts.selectors import racer_name
from racing import broadcasts, timing, timing_signals
from racing.models import PhysicalRun, Ranking, RankingMethod, Submission
from tests.helpers.league import DAY, event

pytestmark = pytest.mark.django_db

CROSSING = timing_signals.Signal("crossing")


def a_run(physical_event, racer, staff):
    return timing.physical_run_start(
        event=physical_event, racer=racer, model_name="sim2real-v3", car="7", timekeeper=staff
    )


def drive(run, *signals):
    """Send signals in order: a number is a crossing at that clock reading [ms]."""
    for signal in signals:
        kind = (
            timing_signals.Signal("crossing", signal)
            if isinstance(signal, int)
            else timing_signals.Signal(signal)
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

    timing.run_signal(run=run, signal=timing_signals.Signal("finish"))
    submission = Submission.objects.get(pk=run.submission_id)
    assert submission.status == Submission.Status.COMPLETED and submission.physical
    assert submission.score_ms == score_ms and submission.qualified
    ranking = Ranking.objects.get(event=race, racer=alice)
    assert ranking.score_ms == score_ms and ranking.submission.physical
    assert alice.notifications.filter(text__contains=race.name).exists()


def test_undo_takes_back_the_last_crossing_and_its_off_tracks(tracks, alice, stella):
    run = a_run(event(physical=True, min_lap_s=1.0), alice, stella)
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
    assert device_post(client, race, json.dumps({"signal": "lap"}), token)[0] == 400
    assert device_post(client, race, json.dumps({"signal": "crossing"}), token) == (
        400,
        {
            "error": "A crossing needs the clock's reading, at_ms: whole milliseconds from 0 "
            "to 2^53."
        },
    )
    # a new token: the old one stops working
    assert device_post(client, race, crossing, timing.timing_token_renew(event=race))[0] == 409
    assert device_post(client, race, crossing, token)[0] == 401
    virtual = event("Virtual")
    assert device_post(client, virtual, crossing, token)[0] == 404


def test_drems_lap_timer_events_are_crossings_at_their_timestamp(client, tracks, alice, stella):
    """The JSON DREM's Raspberry Pi timer sends (leaderboard-timer/timer.js:99-105, 232-241):
    its greeting changes nothing, each lap is a crossing at the Pi's clock, a second gate's
    lap 0.4 s later is refused as a double (the event's shortest lap)."""
    race = event(physical=True, min_lap_s=1.0)
    token = timing.timing_token_renew(event=race)
    hello = {"event": "connected", "timestamp": 1_795_900_000_000, "serverInfo": {}}
    status, state = device_post(client, race, json.dumps(hello), token)
    assert status == 200 and state["on_track"] is False  # nobody on the track: nothing to do
    a_run(race, alice, stella)

    def lap(at: int, gpio: int = 17) -> str:
        return json.dumps({"event": "lap", "timestamp": at, "gpio": gpio, "lapNumber": 1})

    assert device_post(client, race, lap(1_795_900_010_000), token)[0] == 200
    status, state = device_post(client, race, lap(1_795_900_018_123), token)
    assert status == 200 and [lap["time_ms"] for lap in state["laps"]] == [8_123]
    assert device_post(client, race, lap(1_795_900_018_523, gpio=27), token)[0] == 409
    status, said = device_post(client, race, json.dumps({"event": "start"}), token)
    assert status == 400 and "DREM's timer sends lap and connected" in said["error"]
    assert device_post(client, race, json.dumps({"event": "lap"}), token)[0] == 400


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
    assert "No racer is called nobody: check the spelling of their racer name." in response.text


# Racers by racer name (issue 54, item 7)


def named(user, name):
    user.profile.racer_name = name
    user.profile.save(update_fields=["racer_name"])
    return user


def test_it_picks_the_racer_by_racer_name_and_never_by_login_name(tracks, alice, bob, stella):
    from racing.forms import TimedRunForm

    named(alice, "VeraFast")
    named(bob, "VeraSlow")
    racers = timing.racers_timed_by(event=event(physical=True), timekeeper=stella)

    def picked(name):
        data = {"racer": name, "model_name": "sim2real-v3", "car": " 7 "}
        form = TimedRunForm(data, racers=racers)
        return form.cleaned_data if form.is_valid() else form.errors["racer"][0]

    assert picked("VeraFast")["racer"] == alice
    assert picked("verafast")["car"] == "7"
    assert picked("alice") == "No racer is called alice: check the spelling of their racer name."
    assert picked("VeraF") == "No racer is called VeraF: did you mean VeraFast?"
    assert picked("Vera") == (
        "No racer is called Vera, and 2 names hold it (VeraFast, VeraSlow): type the whole "
        "racer name."
    )


def test_the_racer_search_answers_its_timekeeper_with_at_most_ten_racer_names(
    client, tracks, alice, stella
):
    from tests.helpers.accounts import racer

    named(alice, "VeraFast")
    for number in range(12):
        named(racer(f"login{number}"), f"Verano{number:02}")
    race = event(physical=True)
    search = reverse("racing:timekeeper-racers", args=[race.slug])
    client.force_login(alice)
    assert client.get(search, {"q": "ver"}).status_code == 404  # a racer may not search
    client.force_login(stella)
    racers = client.get(search, {"q": "ver"}).json()["racers"]
    assert len(racers) == 10 and racers[0] == "VeraFast" and "Verano00" in racers
    assert client.get(search, {"q": "fast"}).json() == {"racers": ["VeraFast"]}
    assert client.get(search, {"q": "login"}).json() == {"racers": []}  # never a login name
    assert client.get(search, {"q": ""}).json() == {"racers": []}


def test_an_organiser_times_only_their_races_participants_and_learns_of_nobody_else(
    client, tracks, alice, bob, django_capture_on_commit_callbacks
):
    from tests.helpers.accounts import racer

    carol = named(racer("carol"), "CarolQuick")  # on the console, not in alice's race
    named(bob, "BobRapid")
    race = event("Garage night", physical=True, public=False, season=None, organiser=alice)
    race.participants.add(bob)
    search = reverse("racing:timekeeper-racers", args=[race.slug])
    client.force_login(alice)
    assert client.get(search, {"q": "r"}).json() == {"racers": ["BobRapid"]}
    page = reverse("racing:timekeeper", args=[race.slug])
    refused = client.post(page, {"racer": "CarolQuick", "model_name": "m", "car": "3"}).text
    unknown = client.post(page, {"racer": "Nobody", "model_name": "m", "car": "3"}).text
    assert "No racer is called CarolQuick: check the spelling" in refused
    assert "No racer is called Nobody: check the spelling" in unknown  # the same words
    with pytest.raises(timing.TimingRefused, match="No racer is called CarolQuick"):
        a_run(race, carol, alice)  # nor through the service: nothing made, nobody told
    assert not Submission.objects.filter(racer=carol).exists()
    assert (
        client.post(page, {"racer": "bobrapid", "model_name": "m", "car": "3"}).status_code == 302
    )
    assert Submission.objects.get(event=race).racer == bob


# The shortest lap, the longest, and laps far below the others (item 8)


def test_a_crossing_sooner_than_the_events_shortest_lap_is_refused_in_words(tracks, alice, stella):
    race = event(physical=True)
    assert race.min_lap_s == 4.0  # the shortest DeepRacer track at the car's top speed
    run = drive(a_run(race, alice, stella), 10_000)
    with pytest.raises(timing.TimingRefused) as refused:
        drive(run, 11_017)
    assert str(refused.value) == (
        "A crossing 0:01.017 after the last one: shorter than this event's shortest lap (4 s), "
        "so the same crossing twice. Not counted."
    )
    with pytest.raises(timing.TimingRefused, match="the clock went back"):
        drive(run, 9_000)
    run = drive(run, 14_000)
    assert [lap.time_ms for lap in run.submission.laps.all()] == [4_000]


def test_the_shortest_lap_is_one_a_real_car_can_drive(tracks):
    from django.core.exceptions import ValidationError

    with pytest.raises(ValidationError) as refused:
        event(physical=True, min_lap_s=0.1)
    assert "min_lap_s" in refused.value.message_dict


def test_a_lap_longer_than_a_race_is_refused_and_undo_never_overflows(
    client, tracks, alice, stella
):
    race = event(physical=True)
    token = timing.timing_token_renew(event=race)
    run = drive(a_run(race, alice, stella), 0)
    with pytest.raises(timing.TimingRefused, match="longer than a race"):
        drive(run, timing.MAX_LAP_MS + 1)
    with pytest.raises(timing.TimingRefused, match="whole milliseconds"):
        drive(run, 2**62)
    crossing = json.dumps({"signal": "crossing", "at_ms": 2**62})
    assert device_post(client, race, crossing, token)[0] == 400
    assert device_post(client, race, "[" * 100_000, token)[0] == 400  # too deep to read
    run = drive(run, timing.MAX_LAP_MS, "undo", "undo")  # the longest lap, taken back
    assert run.line_crossed_ms is None and run.submission.laps.count() == 0


def test_a_lap_far_below_the_runs_others_is_flagged(tracks, alice, stella):
    from racing import broadcasts

    run = drive(a_run(event(physical=True), alice, stella), 0, 10_000, 20_000, 26_000, 36_000)
    laps = broadcasts.timing_state(run)["laps"]
    assert [lap["far_below"] for lap in laps] == [False, False, True, False]  # 6 s among 10 s


# Lap edits: strike, restore, a missed crossing (item 8)


def finished(race, racer, staff, *crossings):
    run = drive(a_run(race, racer, staff), *crossings, "finish")
    return Submission.objects.get(pk=run.submission_id)


def test_striking_the_best_lap_of_a_finished_run_ranks_it_again_even_when_worse(
    tracks, alice, stella
):
    from racing import lap_edits
    from racing.models import LapEdit

    race = event(physical=True, ranking_method=RankingMethod.BEST_LAP, min_lap_s=1.0)
    slower = finished(race, alice, stella, 0, 8_000)  # a run of one 8 s lap
    faster = finished(race, alice, stella, 0, 9_000, 10_017, 19_017)  # a double press: 1.017 s
    assert Ranking.objects.get(event=race, racer=alice).score_ms == 1_017

    lap = faster.laps.get(number=2)
    lap_edits.lap_strike(lap=lap, by=stella)
    faster.refresh_from_db()
    assert faster.score_ms == 9_000 and faster.qualified
    ranking = Ranking.objects.get(event=race, racer=alice)
    assert (ranking.submission_id, ranking.score_ms) == (slower.pk, 8_000)  # her next best
    lap.refresh_from_db()
    assert not lap.counted and lap.struck_by == stella and lap.struck_at is not None

    assert alice.notifications.filter(text__contains="scored: 0:09.000").exists()

    lap_edits.lap_restore(lap=lap, by=stella)
    assert Ranking.objects.get(event=race, racer=alice).score_ms == 1_017
    edits = LapEdit.objects.filter(submission=faster)
    assert [(edit.action, edit.lap_number, edit.by) for edit in edits] == [
        ("strike", 2, stella),
        ("restore", 2, stella),
    ]
    with pytest.raises(timing.TimingRefused, match="not struck out"):
        lap_edits.lap_restore(lap=lap, by=stella)


def test_a_run_whose_only_counted_lap_is_struck_leaves_the_leaderboard(tracks, alice, stella):
    from racing import lap_edits

    race = event(physical=True, ranking_method=RankingMethod.BEST_LAP)
    run = finished(race, alice, stella, 0, 8_000)
    assert Ranking.objects.filter(event=race, racer=alice).exists()
    lap_edits.lap_strike(lap=run.laps.get(), by=stella)
    run.refresh_from_db()
    assert not run.qualified and run.score_ms is None
    assert not Ranking.objects.filter(event=race, racer=alice).exists()


def test_a_missed_crossing_splits_a_lap_in_two_during_the_run(tracks, alice, stella):
    from racing import lap_edits

    race = event(physical=True, off_track_penalty_s=2.0)
    run = drive(a_run(race, alice, stella), 0, 10_000, "off_track", 30_000, 40_000)
    long_lap = run.submission.laps.get(number=2)  # 20 s and 2 s of penalty: two laps in one
    with pytest.raises(timing.TimingRefused, match="shorter than this event's shortest lap"):
        lap_edits.lap_split(lap=long_lap, first_ms=3_000, by=stella)
    lap_edits.lap_split(lap=long_lap, first_ms=9_000, by=stella)
    laps = run.submission.laps.order_by("number")
    assert [(lap.time_ms, lap.penalty_ms, lap.off_tracks) for lap in laps] == [
        (10_000, 0, 0),
        (11_000, 2_000, 1),  # the off-track stays with the first part
        (11_000, 0, 0),
        (10_000, 0, 0),
    ]
    run = drive(run, "undo")  # the crossing at 40 s, taken back: the clock is as it was
    assert run.line_crossed_ms == 30_000


def test_a_lap_missed_at_the_end_is_added_after_the_finish_only(tracks, alice, stella):
    from racing import lap_edits

    race = event(physical=True, laps_required=2, ranking_method=RankingMethod.FIRST_CONSECUTIVE)
    run = drive(a_run(race, alice, stella), 0, 10_000)
    with pytest.raises(timing.TimingRefused, match="still on the track"):
        lap_edits.lap_add(submission=run.submission, time_ms=9_000, by=stella)
    drive(run, "finish")
    submission = Submission.objects.get(pk=run.submission_id)
    assert not submission.qualified
    lap = lap_edits.lap_add(submission=submission, time_ms=9_000, off_tracks=1, by=stella)
    assert (lap.number, lap.time_ms, lap.penalty_ms) == (2, 11_000, 2_000)
    submission.refresh_from_db()
    assert submission.qualified and submission.score_ms == 10_500
    assert Ranking.objects.get(event=race, racer=alice).score_ms == 10_500


# Qualifying (item 10)


def test_a_best_lap_physical_event_ranks_any_counted_lap(tracks, alice, stella):
    from racing import broadcasts

    race = event(physical=True, ranking_method=RankingMethod.BEST_LAP, laps_required=3)
    run = drive(a_run(race, alice, stella), 0, 9_000, "finish")
    submission = Submission.objects.get(pk=run.submission_id)
    assert submission.qualified and submission.score_ms == 9_000
    assert broadcasts.timing_state(run)["verdict"].endswith("'s run scored 0:09.000.")
    assert race.qualifying_rule == "any counted lap ranks: one is enough to qualify"


def test_the_finish_says_why_a_run_did_not_qualify(tracks, alice, stella):
    from racing import broadcasts

    named(alice, "VeraFast")
    race = event(physical=True, laps_required=3, laps_to_drive=3)
    run = drive(a_run(race, alice, stella), 0, 9_000, 18_000, "finish")
    assert broadcasts.timing_state(run)["verdict"] == (
        "VeraFast's run did not qualify: 2 of the 3 counted laps in a row the event needs."
    )
    assert race.qualifying_rule == "a run ranks once it has 3 counted laps in a row"


# The pages


def test_the_timekeeper_edits_a_runs_laps_from_its_page_and_its_script(
    client, tracks, alice, stella
):
    race = event(physical=True, ranking_method=RankingMethod.BEST_LAP)
    submission = finished(race, alice, stella, 0, 8_000, 16_500)
    page = reverse("racing:timed-run", args=[race.slug, submission.pk])
    edit = reverse("racing:lap-edit", args=[race.slug, submission.pk])
    client.force_login(alice)
    assert client.get(page).status_code == 404
    assert client.post(edit, {"action": "strike", "lap": 1}).status_code == 404

    client.force_login(stella)
    shown = client.get(page).text  # a finished run: its result, and a lap may be added
    assert "run scored 0:08.000." in shown
    assert "Add the lap" in shown and "still on the track" not in shown
    response = client.post(edit, {"action": "strike", "lap": 1}, follow=True)
    assert "Lap 1 is struck out: it no longer counts." in response.text
    assert "Restore lap 1" in response.text and "struck out by" in response.text
    run_page = client.get(submission.get_absolute_url()).text  # the run's page, as racers see it
    assert "Not counted: struck out by the timekeeper" in run_page
    response = client.post(edit, {"action": "split", "lap": 2}, follow=True)
    assert "Say how long the lap&#x27;s first part took, in seconds." in response.text
    response = client.post(
        edit, {"action": "restore", "lap": 1}, headers={"Accept": "application/json"}
    )
    assert response.status_code == 200 and response.json()["score_ms"] == 8_000
    response = client.post(
        edit, {"action": "strike", "lap": 9}, headers={"Accept": "application/json"}
    )
    assert response.status_code == 400  # a lap the run does not have: the request's fault
    assert response.json() == {"error": "Choose one of the run's laps by its number."}
    response = client.post(edit, {"action": "add", "time_s": "7.25"}, follow=True)
    assert "Lap 3 added." in response.text
    assert Submission.objects.get(pk=submission.pk).score_ms == 7_250


def test_the_timekeeper_page_states_the_rule_and_offers_to_copy_the_token(
    client, tracks, alice, stella
):
    race = event(physical=True, ranking_method=RankingMethod.BEST_LAP, min_lap_s=5.5)
    finished(race, alice, stella, 0, 8_000)
    page = reverse("racing:timekeeper", args=[race.slug])
    client.force_login(stella)
    client.post(reverse("racing:timekeeper-token", args=[race.slug]))
    text = client.get(page).text
    assert "any counted lap ranks: one is enough to qualify" in text
    assert "0:08.000" in text  # the finished run's score in "Runs timed"
    assert "A crossing sooner than 5.5 s after the last one is refused" in text
    assert "data-copy-token" in text and "Car number" in text
    assert f"Edit the laps of {racer_name(racer=alice)}'s run" in text


def test_a_racers_race_time_runs_from_their_first_crossing_and_a_later_crossing_is_refused(
    tracks, alice, stella
):
    race = event(physical=True, race_time_min=2, laps_required=1)
    run = a_run(race, alice, stella)
    waiting = broadcasts.timing_state(run)
    assert (waiting["race_time_min"], waiting["race_ends_ms"]) == (2, None)  # not started yet
    run = drive(run, 0, 10_000)
    started = PhysicalRun.objects.get(pk=run.pk).started_at
    ends = broadcasts.timing_state(run)["race_ends_ms"]
    assert ends == round((started + timedelta(minutes=2)).timestamp() * 1000)
    # the racer's two minutes run out on the track: the lap then is not counted
    PhysicalRun.objects.filter(pk=run.pk).update(
        started_at=timezone.now() - timedelta(minutes=2, seconds=5)
    )
    with pytest.raises(
        timing.TimingRefused, match=r"race time \(2 min from the first .*not counted"
    ):
        drive(PhysicalRun.objects.get(pk=run.pk), 20_000)
    run = drive(PhysicalRun.objects.get(pk=run.pk), "undo", "undo")  # back before the start
    assert PhysicalRun.objects.get(pk=run.pk).started_at is None
    assert broadcasts.timing_state(run)["race_ends_ms"] is None
