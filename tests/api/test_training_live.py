"""A model's training as scripts follow it, from a running console (Daphne): its log by pages
after a line, and its live metrics and place in the queue as server-sent events."""

from __future__ import annotations

import threading

import pytest
from pitlane_client import Client

from accounts.tokens import token_create
from tests.api.test_models_api import a_model
from training import streams
from training.models import JobLogLine, RLModel, TrainingJob

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.slow]


def racers_client(owner, url: str) -> Client:
    return Client(url, token_create(owner=owner, name="live", scopes=["read"], days=7)[1])


def test_a_log_is_read_by_pages_after_a_line_and_never_anothers(alice, bob, tracks, daphne_server):
    model = a_model(alice, "logged", status=RLModel.Status.TRAINING)
    job = TrainingJob.objects.create(model=model, status=TrainingJob.Status.IN_PROGRESS)
    for text in ("Training started", "Iteration 1: reward 12.5", "Iteration 2: reward 17.0"):
        JobLogLine.objects.create(job=job, text=text)
    pitlane = racers_client(alice, daphne_server)
    first = pitlane.log(model.pk, limit=2)
    assert [line["text"] for line in first["lines"]] == [
        "Training started",
        "Iteration 1: reward 12.5",
    ]
    assert first["active"] is True
    rest = pitlane.log(model.pk, after=first["next"])
    assert [line["text"] for line in rest["lines"]] == ["Iteration 2: reward 17.0"]
    assert pitlane.log(model.pk, after=rest["next"]) == {
        "lines": [],
        "next": rest["next"],
        "active": True,
    }
    with pytest.raises(Exception, match="No model of yours"):
        racers_client(bob, daphne_server).log(model.pk)


def test_the_training_events_say_the_queue_place_then_each_iteration_until_it_ends(
    alice, tracks, daphne_server
):
    model = a_model(alice, "streamed", status=RLModel.Status.QUEUED)
    job = TrainingJob.objects.create(model=model)
    events = racers_client(alice, daphne_server).training_events(model.pk)
    kind, state = next(events)
    assert kind == "state" and state["status"] == "QUEUED" and state["active"] is True
    assert "queue_words" in state and state["history"] == []

    group = streams.training_group(job.pk)
    point = {"type": "iteration", "number": 1, "reward": 12.5, "completion": 40.0}
    threading.Timer(0.2, streams.announce, (group, point)).start()
    assert next(events) == ("iteration", point)
    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.COMPLETED)
    threading.Timer(0.2, streams.announce_training, (job.pk,)).start()
    kind, status = next(events)
    assert kind == "status" and status["status"] == "COMPLETED" and status["active"] is False
    assert list(events) == []  # the stream ended with the training
