"""A queued job, evaluation or race entry whose task is gone (lost when sending it failed on a
locked database, with a Redis restart, with a worker that died holding it) is found by every
worker's heartbeat (``console.recovery.resume_lapsed``) and sent again, keeping its place in
the queue (issue 42: three jobs read "number 1 in the queue" for an hour)."""

import uuid
from datetime import timedelta

import pytest
from celery import current_app
from django.utils import timezone
from kombu.exceptions import OperationalError

from console import recovery
from jobs import tasks
from racing import tasks as racing_tasks
from racing.models import Submission
from tests.helpers.league import event, race_evaluation
from tests.helpers.models import ready_model
from tests.helpers.training import settings
from training import leases
from training.models import EvaluationJob, TrainingJob
from training.services import model_create

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def queued(owner, name: str, *, age: float = 60) -> TrainingJob:
    """A queued job created ``age`` seconds ago; the test sends no task for it."""
    model = model_create(owner=owner, settings=settings(name=name), validate_reward=False)
    job = model.jobs.get()
    created = timezone.now() - timedelta(seconds=age)
    TrainingJob.objects.filter(pk=job.pk).update(created_at=created)
    return TrainingJob.objects.get(pk=job.pk)


@pytest.fixture
def sent(monkeypatch) -> list[tuple[str, int]]:
    """The tasks sent, in place of the broker."""
    record = []

    def send_task(name, args=None, kwargs=None, **options):  # a task's delay, or by its name
        record.append((name, args[0]))

    monkeypatch.setattr(current_app, "send_task", send_task)
    return record


def test_a_queued_job_whose_task_is_gone_is_sent_again_once_keeping_its_place(
    alice, sent, monkeypatch
):
    first, lost, fresh = queued(alice, "first"), queued(alice, "lost"), queued(alice, "new", age=0)
    place = leases.queue_position(lost)
    monkeypatch.setattr(recovery, "waiting", lambda: {tasks.train.name: {first.pk}})
    recovery.resume_lapsed()
    assert sent == [(tasks.train.name, lost.pk)]  # not the one waiting, nor the one just sent
    recovery.resume_lapsed()
    assert len(sent) == 1  # claimed once: sent again a lease later if no trainer took it
    assert leases.queue_position(TrainingJob.objects.get(pk=lost.pk)) == place == 2
    assert [line.text for line in lost.log_lines.all()] == [leases.QUEUED_LOST]

    TrainingJob.objects.filter(pk=lost.pk).update(lease_expires=timezone.now())  # none took it
    recovery.resume_lapsed()
    assert sent == [(tasks.train.name, lost.pk)] * 2 and lost.log_lines.count() == 1
    run = leases.lease_acquire(job_id=lost.pk, owner="trainer:1")  # a trainer takes it at last
    assert run.attempt == 1 and run.lease_owner == "trainer:1"
    TrainingJob.objects.filter(pk=lost.pk).update(lease_expires=timezone.now())
    assert leases.lost_queued_claim(waiting=set()) == [first]  # the trainer's own: lapsed_claim's
    assert fresh.pk not in {pk for _, pk in sent}


def test_a_queued_evaluation_or_race_entry_whose_task_is_gone_is_sent_again(
    alice, sent, monkeypatch, django_capture_on_commit_callbacks
):
    model = ready_model(alice)
    cup = event("Lost cup")
    plain = EvaluationJob.objects.create(model=model, track=model.track)
    entry, waits = (
        Submission.objects.create(
            event=cup,
            racer=alice,
            model=model,
            model_name=model.name,
            evaluation=race_evaluation(model, cup),
        )
        for _ in range(2)
    )
    old = timezone.now() - timedelta(seconds=60)
    EvaluationJob.objects.update(created_at=old)
    monkeypatch.setattr(recovery, "waiting", lambda: {racing_tasks.race.name: {waits.pk}})
    with django_capture_on_commit_callbacks(execute=True):
        recovery.resume_lapsed()
    assert sorted(sent) == [(racing_tasks.race.name, entry.pk), (tasks.evaluate.name, plain.pk)]
    assert EvaluationJob.objects.get(pk=plain.pk).lease_owner == leases.RESUMING


def test_the_broker_says_which_tasks_wait_in_its_queues(monkeypatch):
    queue = f"lost-tasks-{uuid.uuid4().hex}"  # a queue no worker serves
    monkeypatch.setitem(tasks.train.app.conf.task_routes, "test.lost", {"queue": queue})
    tasks.train.apply_async((4242,), queue=queue)
    tasks.evaluate.apply_async((77,), queue=queue, priority=6)
    try:
        found = tasks.waiting()
    finally:
        with tasks.train.app.connection_for_write() as connection:
            channel = connection.default_channel
            channel.client.delete(*(channel._q_for_pri(queue, p) for p in channel.priority_steps))
    assert 4242 in found[tasks.train.name] and 77 in found[tasks.evaluate.name]


def test_a_job_whose_task_could_not_be_sent_is_queued_not_an_error(
    alice, monkeypatch, django_capture_on_commit_callbacks
):
    def unreachable(name, args):
        raise OperationalError("Error 111 connecting to the broker. Connection refused.")

    monkeypatch.setattr(current_app, "send_task", unreachable)  # services queue by name
    with django_capture_on_commit_callbacks(execute=True) as callbacks:
        model = model_create(owner=alice, settings=settings(name="unsent"), validate_reward=False)
    assert len(callbacks) == 1  # the send was tried, failed and was logged
    assert model.jobs.get().status == TrainingJob.Status.QUEUED  # the heartbeat sends it again
