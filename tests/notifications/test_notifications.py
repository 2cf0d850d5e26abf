"""Notifications: the racer is told in the console (the bell) and, where an email server is
configured, by email, when a training ends or fails, an evaluation ends and a race is scored."""

from __future__ import annotations

import pytest
from django.core import mail
from django.core.exceptions import ImproperlyConfigured
from django.db import connection
from django.test.utils import CaptureQueriesContext
from django.urls import reverse

from console.env import Env
from jobs import evaluation, trainer
from notifications import services
from notifications.models import Notification
from racing.models import Submission
from tests.helpers import league
from tests.helpers.models import ready_model
from tests.helpers.training import queued_job
from training import leases, lifecycle
from training.models import EvaluationJob, EvaluationTrial, TrainingJob

pytestmark = pytest.mark.django_db


def finished_by_the_trainer(job: TrainingJob, status: str, reason: str = "") -> TrainingJob:
    """The job as its trainer leaves it: leased, then ended through the trainer's own path."""
    leased = leases.lease_acquire(job_id=job.pk, owner="test-run")
    TrainingJob.objects.filter(pk=job.pk).update(iterations=3, training_seconds=95)
    leased.iterations, leased.training_seconds = 3, 95
    trainer.Trainer(leased, start_rollouts=lambda *args: None).finish(status, reason=reason)
    return TrainingJob.objects.select_related("model").get(pk=job.pk)


def driven(evaluation_job: EvaluationJob) -> EvaluationJob:
    """The evaluation as its run leaves it before it ends: loaded, then driving."""
    lifecycle.EVALUATION.move(evaluation_job, EvaluationJob.Status.INITIALIZING)
    lifecycle.EVALUATION.move(evaluation_job, EvaluationJob.Status.IN_PROGRESS)
    return evaluation_job


def test_a_trained_jobs_end_tells_its_racer_with_a_link_to_the_model(alice, tracks):
    job = finished_by_the_trainer(queued_job(alice), TrainingJob.Status.COMPLETED)
    notification = Notification.objects.get(recipient=alice)
    assert notification.text == (
        "tiny-oval finished training: 3 iterations in 1:35; it is ready to evaluate."
    )
    assert notification.url == reverse("training:model-detail", args=[job.model.pk])
    assert notification.read_at is None


def test_a_stopped_and_a_failed_training_say_so(alice, tracks):
    stopped = queued_job(alice)
    TrainingJob.objects.filter(pk=stopped.pk).update(stop_requested=True)
    finished_by_the_trainer(stopped, TrainingJob.Status.COMPLETED)
    assert Notification.objects.get().text.startswith("tiny-oval stopped training as you asked")
    Notification.objects.all().delete()
    stopped.model.delete()
    finished_by_the_trainer(queued_job(alice), TrainingJob.Status.FAILED, "Redis was lost.")
    assert Notification.objects.get().text == (
        "tiny-oval's training failed after 1:35: Redis was lost."
    )


def test_an_evaluations_end_is_told_but_a_races_evaluation_waits_for_the_score(alice, tracks):
    model = ready_model(alice)
    done = EvaluationJob.objects.create(model=model, track=model.track, trials=2)
    EvaluationTrial.objects.create(
        evaluation=done, number=1, time_ms=12_345, progress=100, status="lap_complete"
    )
    EvaluationTrial.objects.create(
        evaluation=done, number=2, time_ms=9_000, progress=40, status="off_track"
    )
    evaluation._finish(driven(done), EvaluationJob.Status.COMPLETED)
    told = Notification.objects.get(recipient=alice)
    assert told.text == (
        "straight-ahead's evaluation on Pitlane Oval is done: 1 of 2 laps completed, "
        "best lap 0:12.345."
    )
    assert told.url == reverse("training:evaluation-detail", args=[model.pk, done.pk])

    event = league.event()
    race = league.race_evaluation(model, event)
    Submission.objects.create(
        event=event, racer=alice, model=model, model_name=model.name, evaluation=race
    )
    evaluation._finish(driven(race), EvaluationJob.Status.COMPLETED)
    assert Notification.objects.filter(recipient=alice).count() == 1


def test_a_scored_race_tells_the_racer_its_score(alice, tracks):
    submission = league.scored(league.event(), alice, 61_234, 62_000, 63_000, model_name="fast")
    told = Notification.objects.get(recipient=alice)
    assert told.text.startswith("fast in Time trial is scored: ")
    assert "3 laps completed" in told.text
    assert told.url == reverse("racing:submission-detail", args=[submission.pk])


def test_it_counts_one_lap_in_the_singular(alice, tracks):
    league.scored(league.event(), alice, 61_234, None, None, model_name="short")
    assert Notification.objects.get().text.endswith("it did not qualify (1 lap completed).")

    model = ready_model(alice)
    single = EvaluationJob.objects.create(model=model, track=model.track, trials=1)
    EvaluationTrial.objects.create(
        evaluation=single, number=1, time_ms=12_345, progress=100, status="lap_complete"
    )
    evaluation._finish(driven(single), EvaluationJob.Status.COMPLETED)
    assert "is done: 1 of 1 lap completed, best lap 0:12.345." in (
        Notification.objects.filter(recipient=alice).latest("pk").text
    )


def test_email_goes_out_only_where_an_email_server_is_configured(
    alice, settings, django_capture_on_commit_callbacks
):
    alice.email = "alice@example.org"
    alice.save()
    settings.PITLANE_EMAIL_NOTIFICATIONS = False
    with django_capture_on_commit_callbacks(execute=True):
        services.notification_send(recipient=alice, text="Nothing by email.", url="/models/")
    assert mail.outbox == []

    settings.PITLANE_EMAIL_NOTIFICATIONS = True
    settings.PITLANE_SITE_URL = "https://pitlane.example.org"
    with django_capture_on_commit_callbacks() as callbacks:
        services.notification_send(recipient=alice, text="fast finished training.", url="/m/1/")
    assert mail.outbox == []  # not before the notification is committed
    for callback in callbacks:
        callback()
    (email,) = mail.outbox
    assert email.to == ["alice@example.org"] and email.subject == "Pitlane: fast finished training."
    assert "https://pitlane.example.org/m/1/" in email.body
    assert Notification.objects.filter(recipient=alice).count() == 2  # the bell has both


def test_the_email_server_is_read_from_one_url():
    assert Env({}).email("PITLANE_EMAIL_URL") is None
    url = "smtp+tls://racer%40club:s%3Dcret@mail.example.org:587"
    smtp = Env({"PITLANE_EMAIL_URL": url}).email("PITLANE_EMAIL_URL")
    assert (smtp.host, smtp.port, smtp.user, smtp.password) == (
        "mail.example.org",
        587,
        "racer@club",
        "s=cret",
    )
    assert smtp.use_tls and not smtp.use_ssl
    assert Env({"E": "smtps://mail.example.org"}).email("E").port == 465
    assert "console" in Env({"E": "console://"}).email("E").backend
    with pytest.raises(ImproperlyConfigured, match="must be a URL starting with"):
        Env({"E": "mail.example.org"}).email("E")


def test_the_bell_counts_unread_and_the_page_marks_them_read(alice, bob, client):
    services.notification_send(recipient=alice, text="first", url="/models/")
    services.notification_send(recipient=alice, text="second", url="https://evil.example/")
    services.notification_send(recipient=bob, text="bob's own")
    client.force_login(alice)
    page = client.get(reverse("home")).text
    assert 'aria-label="Notifications, 2 unread"' in page
    listing = client.get(reverse("notifications:list")).text
    assert "first" in listing and "second" in listing and "bob&#x27;s own" not in listing

    first = Notification.objects.get(text="first")
    response = client.get(reverse("notifications:open", args=[first.pk]))
    assert response.status_code == 302 and response["Location"] == "/models/"
    assert 'aria-label="Notifications, 1 unread"' in client.get(reverse("home")).text
    second = Notification.objects.get(text="second")  # not a path here: the list instead
    assert client.get(reverse("notifications:open", args=[second.pk]))["Location"] == (
        reverse("notifications:list")
    )
    bobs = Notification.objects.get(recipient=bob)
    assert client.get(reverse("notifications:open", args=[bobs.pk])).status_code == 404

    services.notification_send(recipient=alice, text="third")
    response = client.post(reverse("notifications:mark-read"), follow=True)
    assert "Marked 1 notification read." in response.text
    assert 'aria-label="Notifications"' in response.text
    assert not Notification.objects.filter(recipient=alice, read_at__isnull=True).exists()
    assert Notification.objects.get(recipient=bob).read_at is None


def test_the_bell_costs_one_query_and_visitors_none(alice, client):
    client.force_login(alice)
    for visitor in ("racer", "visitor"):
        with CaptureQueriesContext(connection) as queries:
            page = client.get(reverse("training:garage" if visitor == "racer" else "login")).text
        counted = [q for q in queries.captured_queries if "notifications_notification" in q["sql"]]
        assert len(counted) == (1 if visitor == "racer" else 0)
        assert ("data-bell" in page) == (visitor == "racer")
        client.logout()


def test_a_notification_that_cannot_be_written_never_changes_how_training_ended(
    alice, tracks, monkeypatch
):
    def broken(**fields):
        raise RuntimeError("the database said no")

    monkeypatch.setattr(Notification.objects, "create", broken)
    job = finished_by_the_trainer(queued_job(alice), TrainingJob.Status.COMPLETED)
    assert job.status == TrainingJob.Status.COMPLETED and not Notification.objects.exists()
