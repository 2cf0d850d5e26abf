"""Re-scorings take turns by racer (issue 55): one racer's line of re-scorings holds another
racer's for at most one of theirs, and a racer who waits is told their place."""

from __future__ import annotations

from datetime import timedelta

import pytest
from django.urls import reverse
from django.utils import timezone

from analysis import selectors, services, tasks
from analysis.models import Rescoring
from analysis.records import Source
from tests.helpers.analysis import SPEED_AND_OFF_TRACK, recorded_by_hand

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def asked(owner, source: Source, times: int = 1) -> list[Rescoring]:
    return [
        services.rescoring_create(
            source=source, owner=owner, reward_function=SPEED_AND_OFF_TRACK, first=None, last=None
        )
        for _ in range(times)
    ]


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_racers_three_rescorings_hold_anothers_for_one_only(alice, bob):
    """Issue 55: bob's one re-scoring waited behind all three of alice's (each task ran the
    re-scoring that queued it); now the second task a worker runs is bob's."""
    first, second, third = asked(alice, Source.of_job(recorded_by_hand(alice)), times=3)
    (bobs,) = asked(bob, Source.of_job(recorded_by_hand(bob)))

    for queued in (first, second):  # the worker takes up the tasks in the order they were sent
        tasks.rescore(queued.pk)

    bobs.refresh_from_db()
    assert bobs.status == Rescoring.Status.DONE, bobs.failure
    assert Rescoring.objects.get(pk=second.pk).status == Rescoring.Status.QUEUED
    for queued in (third, bobs):  # the tasks left run what is left, whatever their ids
        tasks.rescore(queued.pk)
    assert set(Rescoring.objects.values_list("status", flat=True)) == {Rescoring.Status.DONE}


def test_a_racer_served_lately_waits_behind_one_who_was_not(alice, bob):
    alices, bobs = Source.of_job(recorded_by_hand(alice)), Source.of_job(recorded_by_hand(bob))
    (done,) = asked(alice, alices)
    Rescoring.objects.filter(pk=done.pk).update(
        status=Rescoring.Status.DONE, started_at=timezone.now() - timedelta(minutes=1)
    )
    (again,) = asked(alice, alices)  # alice asks again before bob does
    (bobs_first,) = asked(bob, bobs)
    assert selectors.rescorings_in_turn() == [bobs_first.pk, again.pk]


def test_a_waiting_racer_is_told_their_place(alice, bob, client):
    alices_job, bobs_job = recorded_by_hand(alice), recorded_by_hand(bob)
    asked(alice, Source.of_job(alices_job), times=3)
    client.force_login(bob)
    base = reverse("analysis:model", args=[bobs_job.model.pk])
    mine = client.post(f"{base}rescore/", {"reward_function": SPEED_AND_OFF_TRACK}).json()
    assert mine["place"] == 1  # alice's first, then bob's
    assert client.get(mine["url"]).json()["place"] == 1
    Rescoring.objects.filter(owner=alice).update(status=Rescoring.Status.FAILED)
    assert client.get(mine["url"]).json()["place"] == 0
    Rescoring.objects.filter(pk=mine["id"]).update(status=Rescoring.Status.RUNNING)
    assert client.get(mine["url"]).json()["place"] is None
