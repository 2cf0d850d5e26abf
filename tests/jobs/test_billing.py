"""A racer is billed for the time their job drives, not for the time it waits for a simulation
worker (issue 42: three jobs billed 3:54 with no rollout ever started); and a rollout that waits
in a busy simulation queue is not taken for dead and replaced."""

import threading
import time
import uuid
from types import SimpleNamespace

import pytest
from django.db import connection
from django.urls import reverse
from django.utils import timezone

from jobs import rollouts, tasks, trainer
from sandbox import SandboxUnavailable
from tests.helpers.training import queued_job, reload, trainer_initializing, wait_for_job
from tests.services import wait_for
from training import leases, selectors
from training.models import TrainingJob
from training.services import training_stop


def train_in_a_thread(job: TrainingJob, start_rollouts) -> threading.Thread:
    """The trainer of ``job``, run here (not by the suite's training worker), so that the test
    decides when its rollout is sent to the simulation workers."""

    def train() -> None:
        try:
            trainer.run(job.pk, owner="test-billing", start_rollouts=start_rollouts)
        finally:
            connection.close()

    thread = threading.Thread(target=train, name="test-billing-trainer", daemon=True)
    thread.start()
    return thread


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_job_waiting_for_a_simulation_worker_is_billed_from_when_its_car_drives(
    client, alice, tracks, celery_worker_process
):
    job = queued_job(alice)
    held = []  # the simulation queue is busy: no worker takes the job's rollout for now
    thread = train_in_a_thread(job, start_rollouts=lambda job, slot: held.append((job, slot)))
    job = wait_for_job(job, lambda j: j.message == trainer.WAITING_FOR_WORKER, "the trainer")
    first_look = job.clock_at
    job = wait_for_job(
        job, lambda j: j.clock_at > first_look, "the trainer to write its clock again", 30
    )
    assert held and job.status == TrainingJob.Status.INITIALIZING
    clock = selectors.training_clock(job=job)
    assert (clock.seconds, clock.running) == (0.0, False)
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[job.model_id])).text
    assert (
        "Initializing · Waiting for a free simulation worker; the clock starts when the car drives"
        in page
    )
    assert "0:00 used of 10 min" in page

    released = timezone.now()
    for held_job, slot in held:
        tasks.start_rollout(held_job, slot)
    job = wait_for_job(job, lambda j: j.status == TrainingJob.Status.IN_PROGRESS, "the car")
    assert job.message.startswith("Training with 1 simulation worker")
    assert job.log_lines.filter(text__startswith="Training started").exists()
    wait_for(lambda: selectors.training_clock(job=reload(job)).seconds > 0, "a second billed")

    stopped = training_stop(job=reload(job))
    thread.join(timeout=120)
    job = reload(job)
    assert job.status == TrainingJob.Status.COMPLETED
    # Billed from the first beat at the earliest: less than the time since the rollout was sent.
    driven = (stopped.clock_at - released).total_seconds()
    assert 0 < job.training_seconds == stopped.training_seconds < driven


@pytest.mark.django_db(transaction=True)
def test_a_rollout_is_replaced_only_when_taken_for_dead_not_while_it_waits_in_the_queue(
    alice, tracks, settings
):
    job = leases.lease_acquire(job_id=queued_job(alice).pk, owner="this-run")
    sent, in_queue = [], {0}
    run = trainer.Trainer(
        job,
        start_rollouts=lambda job, slot: sent.append(slot.index),
        queued_rollouts=lambda job: in_queue,
    )
    run.channel.start(job.attempt)
    (slot,) = run.slots

    def sent_long_ago() -> None:
        slot.started -= settings.PITLANE_ROLLOUT_STARTUP + 1
        slot.started_wall -= settings.PITLANE_ROLLOUT_STARTUP + 1

    sent_long_ago()  # and still in the queue, behind other jobs' work
    run._watch_workers()
    assert sent == [] and not job.log_lines.exists()

    in_queue.clear()  # gone from the queue, and no worker took it: lost
    run._watch_workers()
    assert sent == [0]
    assert job.log_lines.get().text == (
        "Simulation worker 1's task was lost from the queue before any worker took it; "
        "starting a replacement."
    )

    run.channel.take(0)  # a worker takes the replacement, and starts
    sent_long_ago()
    run._watch_workers()
    assert sent == [0]  # taken just now: it has its own startup time to beat
    sent_long_ago()
    run.channel.client.hset(run.channel.control, "taken:0", slot.started_wall + 1)
    run._watch_workers()  # taken long ago, and never beat
    assert sent == [0, 0]
    assert job.log_lines.order_by("pk").last().text == (
        "Simulation worker 1 stopped answering as it started; starting a replacement."
    )


def test_the_broker_says_which_of_a_jobs_rollouts_wait_in_its_queue(monkeypatch):
    queue = f"billing-{uuid.uuid4().hex}"  # a queue no worker serves
    monkeypatch.setitem(tasks.rollout.app.conf.task_routes, "test.billing", {"queue": queue})
    for job_id, slot, attempt in [(987_654, 1, 3), (987_654, 0, 2), (987_655, 2, 3)]:
        tasks.rollout.apply_async((job_id, slot, attempt, "pitlane-oval"), queue=queue)
    try:
        found = tasks.queued_rollouts(SimpleNamespace(pk=987_654, attempt=3))
    finally:
        with tasks.rollout.app.connection_for_write() as connection:
            channel = connection.default_channel
            channel.client.delete(*(channel._q_for_pri(queue, p) for p in channel.priority_steps))
    assert found == {1}  # not an earlier attempt's, nor another job's


@pytest.mark.django_db(transaction=True)
def test_a_job_no_simulation_worker_takes_fails_unbilled_rather_than_hold_its_trainer(
    alice, tracks, monkeypatch
):
    job = queued_job(alice)
    monkeypatch.setattr(trainer, "WORKER_PATIENCE", 0)  # 30 minutes, as far as the job can tell
    assert trainer.run(job.pk, owner="test-billing", start_rollouts=lambda job, slot: None)
    job = reload(job)
    assert job.status == TrainingJob.Status.FAILED
    assert job.failure_reason == trainer.NO_WORKER
    assert (job.training_seconds, job.iterations) == (0, 0)


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_jobs_clock_stops_while_no_car_drives_and_starts_again_when_one_does(
    alice, tracks, settings, monkeypatch
):
    run = trainer_initializing(alice)
    job = run.job
    run.channel.beat(0)
    run._start_clock()
    run.session_started -= 5  # it drove 5 s
    silent = time.time() - settings.PITLANE_ROLLOUT_SILENCE - 1
    run.channel.client.hset(run.channel.control, "worker:0", silent)  # then its worker died

    run._watch_workers()  # its replacement waits behind other work
    job = reload(job)
    assert (job.status, job.message) == (
        TrainingJob.Status.INITIALIZING,
        trainer.WAITING_FOR_WORKER,
    )
    clock = selectors.training_clock(job=job)
    assert not clock.running and 5 <= clock.seconds < 6
    run._turn()  # the dead worker's last beat does not start it again
    assert not selectors.training_clock(job=reload(job)).running

    run.channel.beat(0)  # the replacement drives
    run._turn()
    job = reload(job)
    assert (job.status, job.message) == (TrainingJob.Status.IN_PROGRESS, run.training_message)
    assert selectors.training_clock(job=job).running
    assert job.log_lines.filter(text__startswith="Training started").count() == 0  # said once

    monkeypatch.setattr(run, "_publish", lambda: None)  # no learner here
    run._recover_redis("Redis restarted and lost the job's keys")  # its workers stop with it
    assert not selectors.training_clock(job=reload(job)).running
    monkeypatch.setattr(trainer, "WORKER_PATIENCE", 0)  # and no worker comes for 30 minutes
    with pytest.raises(trainer.JobFailed, match="You were not billed for the wait"):
        run._watch_workers()


def test_a_rollout_says_it_took_its_task_before_it_reads_or_checks_anything(
    alice, tracks, monkeypatch
):
    job = leases.lease_acquire(job_id=queued_job(alice).pk, owner="this-run")
    channel = trainer.Trainer(job, start_rollouts=None).channel
    channel.start(job.attempt)
    taken_when_checking = []

    def sandbox_checked() -> None:  # it may take seconds on a busy machine
        taken_when_checking.append(set(channel.takings()))
        raise SandboxUnavailable("no sandbox here")

    monkeypatch.setattr(rollouts, "verified", sandbox_checked)
    rollouts.run(job.pk, 0, job.attempt, "pitlane-oval")
    assert taken_when_checking == [{0}]  # not taken for lost from the queue meanwhile
