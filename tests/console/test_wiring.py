"""The real parts, wired: web process → Redis broker → Celery worker → channel layer → websocket."""

import pytest
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import AnonymousUser

from console.consumers import WorkerProbeConsumer
from tests.services import parent_of

pytestmark = pytest.mark.django_db(transaction=True)


def communicator_for(user) -> WebsocketCommunicator:
    communicator = WebsocketCommunicator(WorkerProbeConsumer.as_asgi(), "/ws/system/probe/")
    communicator.scope["user"] = user
    return communicator


async def test_a_task_enqueued_by_the_web_process_runs_on_a_worker_and_answers_over_the_layer(
    stella, celery_worker_process
):
    communicator = communicator_for(stella)
    connected, _ = await communicator.connect()
    assert connected
    await communicator.send_json_to({"action": "probe"})

    sent = await communicator.receive_json_from(timeout=10)
    assert sent == {"type": "probe.sent", "queues": ["training", "simulation", "rescoring"]}
    answers = [await communicator.receive_json_from(timeout=20) for _ in sent["queues"]]
    await communicator.disconnect()

    assert {answer["queue"] for answer in answers} == {"training", "simulation", "rescoring"}
    hostnames = {"training": "test-trainer@", "simulation": "test-sim@"}
    hostnames["rescoring"] = "test-rescore@"
    for answer in answers:
        assert answer["type"] == "probe.result"
        assert parent_of(answer["pid"]) in celery_worker_process.pids  # a pool process of one
        assert answer["worker"].startswith(hostnames[answer["queue"]])  # the queue's own worker
        assert answer["waited_ms"] >= 0


@pytest.mark.parametrize("who", ["anonymous", "racer"])
async def test_only_staff_may_open_the_probe_socket(who, alice):
    user = AnonymousUser() if who == "anonymous" else alice
    communicator = communicator_for(user)
    connected, code = await communicator.connect()
    await communicator.disconnect()
    assert not connected
    assert code == 4403


async def test_an_unknown_action_gets_an_error_not_a_crash(stella):
    communicator = communicator_for(stella)
    await communicator.connect()
    await communicator.send_json_to({"action": "reboot"})
    assert await communicator.receive_json_from() == {
        "type": "error",
        "message": "Unknown action.",
    }
    await communicator.disconnect()


async def test_a_websocket_from_another_site_is_refused_before_anything_else(stella):
    from console.asgi import application

    communicator = WebsocketCommunicator(
        application, "/ws/system/probe/", headers=[(b"origin", b"https://evil.example")]
    )
    connected, code = await communicator.connect()
    await communicator.disconnect()
    assert not connected
    assert code != 4403  # the origin check answered; the consumer never saw it


async def test_a_websocket_from_the_site_itself_reaches_the_consumer():
    from console.asgi import application

    communicator = WebsocketCommunicator(
        application, "/ws/system/probe/", headers=[(b"origin", b"http://127.0.0.1:8000")]
    )
    connected, code = await communicator.connect()
    await communicator.disconnect()
    assert not connected
    assert code == 4403  # refused by the consumer (anonymous), not by the origin check
