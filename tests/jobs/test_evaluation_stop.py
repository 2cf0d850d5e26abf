"""Stop evaluation: the racer stops a running evaluation, which ends CANCELED with the trials it
finished, their video and trace; the model is ready again."""

import pytest
from asgiref.sync import sync_to_async
from django.core.files.storage import default_storage
from django.test import Client
from django.urls import reverse

from jobs import evaluation as runner
from tests.helpers.evaluations import stored
from tests.helpers.live import frame_header, viewer
from tests.helpers.models import ready_model
from tests.services import wait_for
from training import artifacts, leases, services
from training.models import EvaluationJob, RLModel

pytestmark = pytest.mark.usefixtures("tracks")


def stop_url(evaluation: EvaluationJob) -> str:
    return reverse("training:evaluation-stop", args=[evaluation.model_id, evaluation.pk])


def check_stopped_after_its_first_trial(pk: int) -> None:
    evaluation = EvaluationJob.objects.select_related("model").get(pk=pk)
    assert evaluation.status == EvaluationJob.Status.CANCELED, evaluation.failure_reason
    assert evaluation.failure_reason == leases.EVALUATION_STOPPED
    assert evaluation.model.status == RLModel.Status.READY
    trials = list(evaluation.trial_rows.all())
    assert 1 <= len(trials) < evaluation.trials and all(t.completed for t in trials)
    assert default_storage.exists(evaluation.video)
    assert b"lap_complete" in stored(evaluation, artifacts.EVALUATION_TRACE)


@pytest.mark.slow
@pytest.mark.django_db
def test_a_stop_asked_during_a_trial_keeps_the_trials_finished(alice, monkeypatch):
    monkeypatch.setattr(leases, "EVALUATION_STOP_LOOK", 0.0)  # the run looks at every step
    model = ready_model(alice)
    evaluation = services.evaluation_start(
        model=model, settings={"trials": 3, "off_track_penalty": 0}, enqueue=False
    )
    record = runner.EvaluationCar._record

    def stop_after_the_first(self, *args, **kwargs):
        counts = record(self, *args, **kwargs)
        services.evaluation_stop(evaluation=self.evaluation)  # as the racer's button does
        return counts

    monkeypatch.setattr(runner.EvaluationCar, "_record", stop_after_the_first)
    runner.run(evaluation.pk)
    check_stopped_after_its_first_trial(evaluation.pk)
    assert EvaluationJob.objects.get(pk=evaluation.pk).trial_rows.count() == 1


@pytest.mark.django_db
def test_an_evaluation_stopped_before_it_began_is_canceled_and_never_runs(client, alice, bob):
    model = ready_model(alice)
    evaluation = services.evaluation_start(model=model, settings={}, enqueue=False)
    client.force_login(bob)
    assert client.post(stop_url(evaluation)).status_code == 404  # only its owner stops it
    client.force_login(alice)
    assert client.get(stop_url(evaluation)).status_code == 405
    page = client.get(reverse("training:evaluation-detail", args=[model.pk, evaluation.pk]))
    assert "data-evaluation-stop" in page.content.decode()

    response = client.post(stop_url(evaluation), follow=True)
    assert "Stopped: the evaluation had not begun." in response.content.decode()
    assert "data-evaluation-stop" not in response.content.decode()
    evaluation.refresh_from_db()
    assert evaluation.status == EvaluationJob.Status.CANCELED
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY
    assert runner.run(evaluation.pk) is None  # its task, delivered later, finds nothing to do
    again = client.post(stop_url(evaluation), follow=True)
    assert "already ended" in again.content.decode()


@pytest.mark.django_db
def test_a_race_entry_cannot_be_stopped(alice):
    model = ready_model(alice)
    evaluation = services.evaluation_start(model=model, settings={}, enqueue=False)
    from racing.models import Submission

    Submission.objects.create(
        racer=alice, model=model, model_name=model.name, evaluation=evaluation, event=_event()
    )
    with pytest.raises(services.EvaluationRefused, match="cannot be stopped"):
        services.evaluation_stop(evaluation=evaluation)


def _event():
    from tests.helpers.league import event

    return event()


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
async def test_the_racer_stops_a_running_evaluation_on_a_worker(alice, celery_worker_process):
    model = await sync_to_async(ready_model)(alice)
    evaluation = await sync_to_async(services.evaluation_start)(
        model=model, settings={"trials": 5, "off_track_penalty": 1}
    )
    # Watched, it drives in real time, so the stop lands in its second trial.
    communicator = await viewer(f"/ws/evaluations/{evaluation.pk}/", alice)
    connected, _ = await communicator.connect()
    assert connected
    while True:
        message = await communicator.receive_from(timeout=60)
        if isinstance(message, bytes):
            frame_header(message)
            await communicator.send_json_to({"type": "ack"})
        elif '"type": "trial"' in message:
            break

    def stop() -> int:
        client = Client()
        client.force_login(alice)
        return client.post(stop_url(evaluation)).status_code

    assert await sync_to_async(stop)() == 302
    await communicator.disconnect()

    def ended() -> bool:
        return not EvaluationJob.objects.get(pk=evaluation.pk).is_active

    await sync_to_async(wait_for)(ended, "the evaluation to stop", timeout=60)
    await sync_to_async(check_stopped_after_its_first_trial)(evaluation.pk)


@pytest.mark.django_db
def test_a_run_that_died_while_stopping_is_ended_by_the_next_and_said_without_its_video(
    alice, monkeypatch, django_capture_on_commit_callbacks
):
    model = ready_model(alice)
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.EVALUATING)
    evaluation = EvaluationJob.objects.create(
        model=model,
        track=model.track,
        status=EvaluationJob.Status.STOPPING,
        lease_owner=leases.RESUMING,  # claimed by leases.lapsed_evaluations for this run
    )
    announced = []
    monkeypatch.setattr(runner.streams, "announce", lambda group, status: announced.append(group))
    with django_capture_on_commit_callbacks() as after_commit:
        assert runner.run(evaluation.pk) is None
        assert announced == []  # nothing said, nor the model freed, under the row's lock
        assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.EVALUATING
    for callback in after_commit:
        callback()
    evaluation.refresh_from_db()
    assert evaluation.status == EvaluationJob.Status.CANCELED
    assert evaluation.failure_reason == leases.EVALUATION_STOPPED_UNSAVED
    assert "without them" in evaluation.failure_reason and not evaluation.video
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.READY
    assert announced == [runner.streams.evaluation_group(evaluation.pk)]
