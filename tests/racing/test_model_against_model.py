"""Model against model through the league (Event.cars): a submission races the leaders' models,
a live turn races the next racers in the queue; each car's evaluation keeps its own trials,
trace, video and score, and the cars see and hit one another."""

from __future__ import annotations

import csv
import html
import io

import pytest
from django.core.files.storage import default_storage
from django.urls import reverse
from django.utils.html import strip_tags

from accounts.selectors import racer_name
from racing import live_races, services
from racing.models import Division, LiveEntry, Racer, Submission
from tests.helpers import accounts
from tests.helpers.league import event, scored
from tests.helpers.models import ready_model
from training import artifacts, leases
from training import services as training_services
from training.models import EvaluationJob, RLModel

pytestmark = pytest.mark.django_db

ONE_LAP = {"laps_required": 1, "laps_to_drive": 1}  # a race of one lap: the cars' laps cost time


@pytest.fixture
def pros(alice, bob):
    """Three racers of the Pro division, where model against model is raced."""
    racers = [alice, bob, accounts.racer("carol")]
    for racer in racers:
        Racer.objects.filter(pk=Racer.of(racer).pk).update(division=Division.PRO)
    return racers


def trace_of(evaluation: EvaluationJob) -> list[dict]:
    name = artifacts.path(
        evaluation.model, artifacts.evaluation_prefix(evaluation) + artifacts.EVALUATION_TRACE
    )
    with default_storage.open(name) as handle:
        return list(csv.DictReader(io.StringIO(handle.read().decode())))


def shown(page: str) -> str:
    """A page's text as a person reads it: no tags, no entities."""
    return html.unescape(strip_tags(page))


def leader(race, racer, model: RLModel, score_ms: int) -> Submission:
    """``racer`` ranked in ``race`` with ``model``'s best checkpoint."""
    submission = scored(race, racer, score_ms, score_ms, score_ms)
    Submission.objects.filter(pk=submission.pk).update(model=model)
    return submission


@pytest.mark.slow
def test_a_submission_races_the_leaders_models_and_each_car_keeps_its_own_race(
    client, tracks, pros, django_capture_on_commit_callbacks
):
    alice, bob, carol = pros
    race = event("Head to model", division=Division.PRO, cars=2, **ONE_LAP)
    scored(race, bob, 20_000, 20_000, 20_000)  # the leader, whose model was deleted since
    carols = ready_model(carol, name="carols")
    leader(race, carol, carols, 30_000)  # the next takes his place

    with django_capture_on_commit_callbacks() as sent:  # one task: the race's first car's
        submission = services.submission_create(racer=alice, event=race, model=ready_model(alice))
    assert len(sent) == 1
    lead = submission.evaluation
    rivals = list(lead.grid.all())
    assert [(r.model, r.grid_position, r.rival) for r in rivals] == [(carols, 1, True)]
    with pytest.raises(training_services.ModelBusy, match="racing against another racer"):
        training_services.model_delete(model=carols)
    with pytest.raises(training_services.EvaluationRefused, match="drives to its end"):
        training_services.evaluation_stop(evaluation=rivals[0])
    RLModel.objects.filter(pk=carols.pk).update(status=RLModel.Status.TRAINING)  # it may train

    told = carol.notifications.count()
    services.submission_run(submission_id=submission.pk)
    submission.refresh_from_db()
    assert submission.status == Submission.Status.COMPLETED and submission.laps.count() == 1
    cars = [EvaluationJob.objects.get(pk=car.pk) for car in (lead, *rivals)]
    assert {car.status for car in cars} == {EvaluationJob.Status.COMPLETED}
    traces = [trace_of(car) for car in cars]
    for car, trace in zip(cars, traces, strict=True):
        assert car.video and car.trial_rows.count() == 1  # each car its own lap and video
        assert {row["episode"] for row in trace} == {"0"}
    # the cars drove together, each from its place on the grid, and ran into one another
    starts = [(float(t[0]["X"]), float(t[0]["Y"])) for t in traces]
    assert len(set(starts)) == 2
    crashes = [sum(trial.crashes for trial in car.trial_rows.all()) for car in cars]
    assert sum(crashes) >= 1
    for car in cars:
        penalties = sum(trial.penalty_ms for trial in car.trial_rows.all())
        counted = sum(trial.crashes for trial in car.trial_rows.all()) * 5_000
        assert penalties >= counted  # each crash costs the event's 5 s
    # the submission's page lists the race's cars, each with its own laps and crashes
    client.force_login(alice)
    page = client.get(submission.get_absolute_url()).text
    assert "The race" in page and "carols" in page and "Model against model: 2 cars" in page
    client.force_login(carol)  # the rival's owner finds the race on their model's page, named
    entry = f"aced as the rival in {racer_name(racer=alice)}'s entry"
    listed = shown(client.get(reverse("training:model-detail", args=[carols.pk])).text)
    assert f"R{entry}, Head to model" in listed
    url = reverse("training:evaluation-detail", args=[carols.pk, rivals[0].pk])
    page = shown(client.get(url).text)
    assert f"r{entry}, Head to model" in page and "Stop evaluation" not in page
    assert "straight-ahead" in page  # alice's model, first on the grid
    # the rival's owner: the model as it was, not told, nothing submitted for them
    assert RLModel.objects.get(pk=carols.pk).status == RLModel.Status.TRAINING
    assert carol.notifications.count() == told
    assert race.submissions.filter(racer=carol).count() == 1


@pytest.mark.slow
def test_a_live_turn_puts_the_next_racers_on_the_grid_and_scores_each(tracks, pros, stella):
    alice, bob, carol = pros
    race = event("Live heads", division=Division.PRO, cars=2, **ONE_LAP)
    session = live_races.live_session_open(event=race, facilitator=stella)
    for racer in (alice, bob, carol):
        live_races.live_entry_join(session=session, racer=racer, model=ready_model(racer))

    first = live_races.live_turn_launch(session=session)
    driving = list(session.entries.filter(status=LiveEntry.Status.DRIVING).order_by("position"))
    assert [entry.racer for entry in driving] == [alice, bob]
    lead, second = (entry.submission.evaluation for entry in driving)
    assert first == driving[0] and second.grid_leader == lead and second.grid_position == 1
    assert not second.rival and second.real_time  # bob's own race: his model is SUBMITTING
    assert carol.notifications.filter(text__startswith="You are next in Live heads").exists()
    # what lapses or is lost is the race's first car, whose run drives both
    EvaluationJob.objects.filter(pk__in=(lead.pk, second.pk)).update(
        real_time=False,
        status=EvaluationJob.Status.IN_PROGRESS,
        lease_owner="gone:1:dead",
        lease_expires=lead.created_at,
    )
    assert [e.pk for e in leases.lapsed_evaluations()] == [lead.pk]
    EvaluationJob.objects.filter(pk__in=(lead.pk, second.pk)).update(
        status=EvaluationJob.Status.QUEUED, lease_owner="", lease_expires=None
    )

    services.submission_run(submission_id=driving[0].submission_id)
    for entry in driving:
        entry.refresh_from_db()
        assert entry.status == LiveEntry.Status.DONE
        assert entry.submission.status == Submission.Status.COMPLETED
        assert entry.submission.laps.count() == 1
    assert {r.racer for r in race.rankings.all()} <= {alice, bob}
    assert RLModel.objects.get(pk=driving[1].model_id).status == RLModel.Status.READY
