"""Live races (racing.live_races): a queue of racers' models, ordered by the facilitator, each
turn a submission driven in real time at the racer's speed multiplier."""

from __future__ import annotations

import pytest

from accounts.selectors import racer_name
from racing import broadcasts, live_races
from racing.models import LiveEntry, Submission
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from training.models import scaled_speeds

pytestmark = pytest.mark.django_db

_L = LiveEntry.Status


def order(session) -> list[str]:
    waiting = session.entries.filter(status=_L.WAITING).order_by("position", "pk")
    return [entry.racer.username for entry in waiting]


def test_the_queue_takes_racers_in_order_and_the_facilitator_reorders_it(
    tracks, alice, bob, stella
):
    race = event("Live cup")
    session = live_races.live_session_open(
        event=race, facilitator=stella, min_speed=0.8, max_speed=1.2
    )
    model = ready_model(alice)
    with pytest.raises(live_races.LiveRefused, match=r"from 0\.8 to 1\.2"):
        live_races.live_entry_join(session=session, racer=alice, model=model, speed=1.5)
    first = live_races.live_entry_join(session=session, racer=alice, model=model, speed=1.2)
    second = live_races.live_entry_join(session=session, racer=bob, model=ready_model(bob))
    another = ready_model(bob, name="another")
    with pytest.raises(live_races.LiveRefused, match="in the queue already"):
        live_races.live_entry_join(session=session, racer=bob, model=another)
    assert order(session) == ["alice", "bob"]
    live_races.live_entry_move(entry=second, places=-1)
    assert order(session) == ["bob", "alice"]
    live_races.live_entry_remove(entry=first)
    assert order(session) == ["bob"]
    live_races.live_entry_restart(entry=first)  # taken out, then put back at the head
    assert order(session) == ["alice", "bob"]


def test_a_turn_is_a_real_time_submission_at_the_racers_speed_and_the_next_racer_is_told(
    tracks, alice, bob, stella
):
    race = event("Live cup")
    session = live_races.live_session_open(event=race, facilitator=stella)
    live_races.live_entry_join(session=session, racer=alice, model=ready_model(alice), speed=0.5)
    live_races.live_entry_join(session=session, racer=bob, model=ready_model(bob))

    entry = live_races.live_turn_launch(session=session)
    assert entry.racer == alice and entry.status == _L.DRIVING
    evaluation = entry.submission.evaluation
    assert evaluation.real_time and evaluation.speed_multiplier == 0.5
    model_speeds = [action["speed"] for action in entry.model.action_space]
    driven = [action["speed"] for action in evaluation.environment_settings()["action_space"]]
    assert driven == [speed * 0.5 for speed in model_speeds]
    # never past the car's 4 m/s, nor under its 0.1
    fast = [{"steering_angle": 0.0, "speed": 3.0}, {"steering_angle": 0.0, "speed": 0.1}]
    assert [a["speed"] for a in scaled_speeds(fast, 1.5)] == pytest.approx([4.0, 0.15])
    assert [a["speed"] for a in scaled_speeds(fast, 0.5)] == [1.5, 0.1]
    assert bob.notifications.filter(text__startswith="You are next in Live cup").exists()
    with pytest.raises(live_races.LiveRefused, match="A turn is driving"):
        live_races.live_turn_launch(session=session)


def test_when_a_turn_ends_autolaunch_starts_the_next(tracks, alice, bob, stella):
    race = event("Live cup")
    session = live_races.live_session_open(event=race, facilitator=stella, autolaunch=True)
    live_races.live_entry_join(session=session, racer=alice, model=ready_model(alice))
    live_races.live_entry_join(session=session, racer=bob, model=ready_model(bob))
    turn = live_races.live_turn_launch(session=session)

    Submission.objects.filter(pk=turn.submission_id).update(status=Submission.Status.COMPLETED)
    live_races.live_turn_ended(submission=turn.submission)
    turn.refresh_from_db()
    assert turn.status == _L.DONE
    following = session.entries.get(racer=bob)
    assert following.status == _L.DRIVING and following.submission is not None


def test_only_staff_and_the_organiser_run_a_live_race_and_never_a_physical_one(
    client, tracks, alice, stella
):
    from django.urls import reverse

    race = event("Live cup")
    assert not live_races.may_facilitate(event=race, user=alice)
    assert live_races.may_facilitate(event=race, user=stella)
    with pytest.raises(live_races.LiveRefused, match="raced by real cars"):
        live_races.live_session_open(event=event("Track day", physical=True), facilitator=stella)
    client.force_login(alice)
    page = reverse("racing:live-race", args=[race.slug])
    assert "is not raced live yet" in client.get(page).text
    assert client.post(reverse("racing:live-race-launch", args=[race.slug])).status_code == 404


def test_a_racer_leaves_the_queue_and_nobody_else_can_take_them_out(
    client, tracks, alice, bob, stella
):
    from django.urls import reverse

    race = event("Live cup")
    session = live_races.live_session_open(event=race, facilitator=stella)
    entry = live_races.live_entry_join(session=session, racer=alice, model=ready_model(alice))
    leave = reverse("racing:live-entry-leave", args=[race.slug, entry.pk])
    client.force_login(bob)
    assert client.post(leave).status_code == 404
    client.force_login(alice)
    assert "Leave the queue" in client.get(reverse("racing:live-race", args=[race.slug])).text
    assert "You left the queue." in client.post(leave, follow=True).text
    entry.refresh_from_db()
    assert entry.status == _L.REMOVED


def test_the_queue_says_what_each_multiplier_drives_and_moves_only_what_can_move(
    tracks, alice, bob, stella
):
    race = event("Live cup")
    session = live_races.live_session_open(event=race, facilitator=stella)
    live_races.live_entry_join(session=session, racer=alice, model=ready_model(alice), speed=0.8)
    live_races.live_entry_join(session=session, racer=bob, model=ready_model(bob), speed=1.2)
    first, second = broadcasts.queue_state(session)["entries"]  # both models drive at 4 m/s
    assert (first["place"], first["first_waiting"], first["last_waiting"]) == (1, True, False)
    assert (second["place"], second["first_waiting"], second["last_waiting"]) == (2, False, True)
    assert (first["top_speed"], first["capped"]) == (pytest.approx(3.2), False)
    assert (second["top_speed"], second["capped"]) == (4.0, True)  # 4.8 m/s asked, 4 driven


def test_a_broadcast_opened_after_the_winner_was_shown_shows_it_until_hidden(
    client, tracks, alice, stella
):
    from django.urls import reverse

    race = event("Live cup")
    live_races.live_session_open(event=race, facilitator=stella)
    scored(race, alice, 20_000, 21_000, 22_000)
    state = reverse("racing:broadcast-state", args=[race.slug])
    assert client.get(state).json()["winner"] is None
    client.force_login(stella)
    winner = reverse("racing:winner", args=[race.slug])
    nobody = event("Empty cup")
    live_races.live_session_open(event=nobody, facilitator=stella)
    empty = reverse("racing:winner", args=[nobody.slug])
    assert "there is no winner to show" in client.post(empty, follow=True).text
    nobody.refresh_from_db()
    assert nobody.winner_shown_at is None  # nothing armed to cover a race to come
    shown = client.post(winner, follow=True).text
    assert f"The broadcast shows the winner: {racer_name(racer=alice)}." in shown
    assert "Hide the winner" in shown
    client.logout()  # a fresh broadcast, anyone's
    assert client.get(state).json()["winner"] == {
        "place": 1,
        "racer": racer_name(racer=alice),
        "model_name": "m",
        "score_ms": 21_000,
        "physical": False,
    }
    client.force_login(stella)
    client.post(winner, {"show": "0"})
    assert client.get(state).json()["winner"] is None


def test_the_join_form_is_offered_only_to_a_racer_with_a_model_not_yet_queued(
    client, tracks, alice, bob, stella
):
    from django.urls import reverse

    race = event("Live cup")
    session = live_races.live_session_open(event=race, facilitator=stella)
    page = reverse("racing:live-race", args=[race.slug])
    client.force_login(stella)  # staff without a model: the controls, no join form
    text = client.get(page).text
    assert "Launch the next turn" in text and "Join the queue</button>" not in text
    client.force_login(bob)
    assert "You have no ready model to race." in client.get(page).text
    live_races.live_entry_join(session=session, racer=alice, model=ready_model(alice))
    client.force_login(alice)
    text = client.get(page).text
    assert "Leave the queue" in text and "Join the queue</button>" not in text
