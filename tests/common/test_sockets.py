"""A consumer whose channel layer fails (Redis down) closes its socket with 4503, which the pages
retry, and the other sockets of the process with it; never a traceback (a handshake's 500)."""

import pytest
import redis
from asgiref.sync import sync_to_async
from channels_redis.core import RedisChannelLayer

from common.sockets import TRY_AGAIN_LATER
from tests.helpers.league import event
from tests.helpers.live import viewer
from tests.services import free_port

pytestmark = pytest.mark.django_db(transaction=True)


async def test_a_handshake_while_redis_is_down_is_accepted_and_closed_to_try_again(
    settings, tracks
):
    race = await sync_to_async(event)("Outage cup")
    layer = settings.CHANNEL_LAYERS["default"]
    host = {**layer["CONFIG"]["hosts"][0], "address": f"redis://127.0.0.1:{free_port()}/0"}
    settings.CHANNEL_LAYERS = {"default": {**layer, "CONFIG": {**layer["CONFIG"], "hosts": [host]}}}

    communicator = await viewer(f"/ws/events/{race.pk}/")
    connected, _ = await communicator.connect(timeout=5)
    assert connected
    assert await communicator.receive_output(timeout=5) == {
        "type": "websocket.close",
        "code": TRY_AGAIN_LATER,
    }
    await communicator.wait()


async def test_redis_failing_under_one_socket_closes_every_socket_of_the_process(
    monkeypatch, tracks
):
    race = await sync_to_async(event)("Outage cup")
    first, second = viewer(f"/ws/events/{race.pk}/"), viewer(f"/ws/events/{race.pk}/")
    first, second = await first, await second
    for communicator in (first, second):
        assert (await communicator.connect())[0]

    async def lost(*args) -> None:
        raise redis.ConnectionError("Connection closed by server.")

    monkeypatch.setattr(RedisChannelLayer, "group_discard", lost)
    await first.send_input({"type": "websocket.disconnect", "code": 1001})  # its leaving fails
    # (after the layer's blocking pop it may hold, of 5 s at most, is given up)
    assert await second.receive_output(timeout=10) == {
        "type": "websocket.close",
        "code": TRY_AGAIN_LATER,
    }
    await first.wait()
    await second.disconnect()
