"""Statuses move only as their lifecycle lists (training.lifecycle: a model, a training job, an
evaluation; racing.services.SUBMISSION: a race entry; racing.live_races.LIVE_ENTRY: a place in a
live race's queue), one conditional write at a time."""

import ast
from datetime import timedelta
from pathlib import Path

import pytest
from django.utils import timezone

from racing.live_races import LIVE_ENTRY
from racing.models import Submission
from racing.services import SUBMISSION
from tests.helpers.models import ready_model
from tests.helpers.training import settings
from training import leases, lifecycle
from training.leases import LeaseLost
from training.models import EvaluationJob, RLModel, TrainingJob
from training.services import model_create, training_stop

pytestmark = pytest.mark.django_db

ROOT = Path(__file__).resolve().parents[2]
Status = RLModel.Status
Job = TrainingJob.Status

LIFECYCLES = {
    "model": (lifecycle.MODEL, set()),
    "training job": (lifecycle.TRAINING_JOB, set()),
    # the racer may stop an evaluation (stopping, then canceled); a race entry runs to its end
    "evaluation": (lifecycle.EVALUATION, set()),
    "race entry": (SUBMISSION, {Job.INITIALIZING, Job.STOPPING, Job.CANCELED}),
    "live race's queue entry": (LIVE_ENTRY, set()),
}


@pytest.mark.parametrize("name", LIFECYCLES)
def test_every_status_says_where_it_may_go(name):
    table, unreachable = LIFECYCLES[name]
    statuses = set(table.model._meta.get_field("status").get_choices(include_blank=False))
    values = {value for value, _ in statuses}
    assert set(table.moves) == values
    assert all(ends <= values for ends in table.moves.values())
    assert table.born <= values
    assert set().union(*table.moves.values()) | table.born == values - unreachable


def test_no_status_is_written_but_by_a_move():
    # The lifecycles are the only writers of a status: no update, assignment or save of one
    # anywhere else in the apps.
    writes = []
    for package in ("analysis", "console", "notifications", "racing", "training"):
        for path in (ROOT / package).rglob("*.py"):
            if path.name == "lifecycle.py" or "migrations" in path.parts:
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                    keywords = {keyword.arg for keyword in node.keywords}
                    fields = [k.value for k in node.keywords if k.arg == "update_fields"]
                    if node.func.attr == "update" and "status" in keywords:
                        writes.append(f"{path.relative_to(ROOT)}:{node.lineno}")
                    if fields and "status" in ast.unparse(fields[0]):
                        writes.append(f"{path.relative_to(ROOT)}:{node.lineno}")
                if isinstance(node, ast.Assign) and any(
                    isinstance(target, ast.Attribute) and target.attr == "status"
                    for target in node.targets
                ):
                    writes.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert writes == []


def test_a_stop_that_lands_while_the_trainer_starts_wins(alice, tracks):
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(status=Status.STOPPING)
    assert not lifecycle.MODEL.move(model.pk, Status.TRAINING)
    assert lifecycle.MODEL.move(model.pk, Status.READY)
    model.refresh_from_db()
    assert model.status == Status.READY


def test_a_model_is_deleted_only_from_ready_or_error_and_only_once(alice, tracks):
    model = ready_model(alice)
    deletable = frozenset(RLModel.DELETABLE)
    assert lifecycle.MODEL.move(model, Status.DELETING, only_from=deletable)
    assert model.status == Status.DELETING
    assert not lifecycle.MODEL.move(model, Status.DELETING, only_from=deletable)  # a second one
    assert not lifecycle.MODEL.move(model, Status.EVALUATING)
    assert lifecycle.MODEL.move(model, Status.READY)  # the delete failed: the model is given back


def test_an_evaluation_that_ends_late_leaves_a_model_it_no_longer_drives_alone(alice, tracks):
    model = ready_model(alice)
    driving = frozenset({Status.EVALUATING, Status.SUBMITTING})
    assert lifecycle.MODEL.move(model, Status.SUBMITTING, only_from=frozenset({Status.READY}))
    assert not lifecycle.MODEL.move(model, Status.EVALUATING, only_from=frozenset({Status.READY}))
    assert lifecycle.MODEL.move(model, Status.READY, only_from=driving)
    RLModel.objects.filter(pk=model.pk).update(status=Status.DELETING)
    assert not lifecycle.MODEL.move(model.pk, Status.READY, only_from=driving)
    model.refresh_from_db()
    assert model.status == Status.DELETING


def test_a_stop_that_lands_as_a_trainer_takes_the_job_up_leaves_it_stopping(alice, tracks):
    # The racer presses Stop after a trainer run took the job's lease, before it prepared: the
    # run finds the job STOPPING, not INITIALIZING over the racer's stop.
    model = model_create(owner=alice, settings=settings(), validate_reward=False)
    run = leases.lease_acquire(job_id=model.jobs.get().pk, owner="trainer:test")
    training_stop(job=run)
    assert not leases.move(run, Job.INITIALIZING, message="Preparing the trainer")
    assert run.status == Job.STOPPING and run.stop_requested
    assert TrainingJob.objects.get(pk=run.pk).message.startswith("Saving the model")
    assert leases.move(run, Job.COMPLETED)  # what the run does next: it ends the job
    assert not leases.move(run, Job.STOPPING)  # and nothing moves an ended job again


def test_a_job_stopped_before_any_run_is_canceled_for_good(alice, tracks):
    model = model_create(owner=alice, settings=settings(), validate_reward=False)
    job = training_stop(job=model.jobs.get())
    assert job.status == Job.CANCELED and job.failure_reason == "Stopped before training began."
    model.refresh_from_db()
    assert model.status == Status.ERROR
    assert leases.lease_acquire(job_id=job.pk, owner="trainer:late") is None  # no run takes it up
    assert not lifecycle.TRAINING_JOB.move(job, Job.INITIALIZING)


def test_only_the_run_holding_the_lease_moves_a_job_and_never_by_a_plain_write(alice, tracks):
    model = model_create(owner=alice, settings=settings(), validate_reward=False)
    first = leases.lease_acquire(job_id=model.jobs.get().pk, owner="trainer:first")
    TrainingJob.objects.filter(pk=first.pk).update(lease_expires=None)  # its worker died
    second = leases.lease_acquire(job_id=first.pk, owner="trainer:second")
    with pytest.raises(LeaseLost):
        leases.move(first, Job.INITIALIZING)
    assert leases.move(second, Job.INITIALIZING)
    with pytest.raises(ValueError, match=r"leases\.move"):
        leases.write(second, status=Job.IN_PROGRESS)


def test_an_evaluation_starts_over_only_while_it_is_unfinished(alice, tracks):
    evaluation = EvaluationJob.objects.create(model=ready_model(alice), track=tracks[0])
    assert lifecycle.EVALUATION.move(evaluation, Job.INITIALIZING)
    assert lifecycle.EVALUATION.move(evaluation, Job.IN_PROGRESS)
    assert lifecycle.EVALUATION.move(evaluation, Job.INITIALIZING)  # redelivered: start over
    assert not lifecycle.EVALUATION.move(evaluation, Job.COMPLETED)  # it has not driven yet
    assert lifecycle.EVALUATION.move(evaluation, Job.IN_PROGRESS)
    assert lifecycle.EVALUATION.move(evaluation, Job.COMPLETED)
    assert not lifecycle.EVALUATION.move(evaluation, Job.INITIALIZING)
    assert not lifecycle.EVALUATION.move(evaluation, Job.FAILED)


def test_a_race_entry_is_scored_again_but_a_failed_one_stays_failed(alice, tracks):
    from tests.helpers.league import event

    entry = Submission.objects.create(event=event(), racer=alice, model_name="m")
    assert not SUBMISSION.move(entry, Job.COMPLETED)  # not driven yet
    assert SUBMISSION.move(entry, Job.IN_PROGRESS)
    assert SUBMISSION.move(entry, Job.COMPLETED, score_ms=30_000)
    assert SUBMISSION.move(entry, Job.COMPLETED, score_ms=29_000)  # the same laps, scored again
    assert Submission.objects.get(pk=entry.pk).score_ms == 29_000
    failed = Submission.objects.create(event=entry.event, racer=alice, model_name="n")
    assert SUBMISSION.move(failed, Job.IN_PROGRESS)
    assert SUBMISSION.move(failed, Job.FAILED)
    assert not SUBMISSION.move(failed, Job.COMPLETED)


def test_a_job_whose_trainer_died_is_claimed_once_for_a_new_run(alice, tracks):
    # What every worker's heartbeat does: a lapsed lease is claimed by one look, and the job is
    # sent for again only if no run took it up within another lease.
    model = model_create(owner=alice, settings=settings(), validate_reward=False)
    run = leases.lease_acquire(job_id=model.jobs.get().pk, owner="trainer:dead")
    assert leases.move(run, Job.INITIALIZING)
    assert leases.lapsed_claim() == []  # its lease is alive
    past = timezone.now() - timedelta(seconds=1)
    TrainingJob.objects.filter(pk=run.pk).update(lease_expires=past)
    assert [job.pk for job in leases.lapsed_claim()] == [run.pk]
    assert leases.lapsed_claim() == []  # claimed once: one new run is sent for
    assert TrainingJob.objects.get(pk=run.pk).log_lines.filter(text=leases.LAPSED).count() == 1
    with pytest.raises(LeaseLost):  # the old run, were it alive, no longer writes
        leases.write(run, message="still here")
    TrainingJob.objects.filter(pk=run.pk).update(lease_expires=past)  # that run never came
    assert [job.pk for job in leases.lapsed_claim()] == [run.pk]
    resumed = leases.lease_acquire(job_id=run.pk, owner="trainer:new")
    assert resumed.attempt == 2 and resumed.lease_owner == "trainer:new"
    assert leases.lapsed_claim() == []
    assert TrainingJob.objects.get(pk=run.pk).log_lines.filter(text=leases.LAPSED).count() == 1
