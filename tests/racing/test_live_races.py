"""Live races (racing.live_races): a queue of racers' models, ordered by the facilitator, each
turn a submission driven in real time at the racer's speed multiplier."""

from __future__ import annotations

import pytest

from racing import live_races
from racing.models import LiveEntry, Submission
from tests.helpers.league import event
from tests.helpers.models import ready_model
from training.models import scaled_speeds

pytestmark = pytest.mark.django_db

_E = LiveEntry.Status


def order(session) -> list[str]:
    waiting = session.entries.filter(status=_E.WAITING).order_by("position", "pk")
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
    assert entry.racer == alice and entry.status == _E.DRIVING
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
    assert turn.status == _E.DONE
    following = session.entries.get(racer=bob)
    assert following.status == _E.DRIVING and following.submission is not None


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
    assert entry.status == _E.REMOVED
