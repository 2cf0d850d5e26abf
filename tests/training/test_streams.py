"""Live streams over the real ASGI application (origin check, sessions, the Redis channel layer)."""

import asyncio
import threading
import time
import tracemalloc

import pytest
from asgiref.sync import sync_to_async
from channels.layers import get_channel_layer
from channels.testing import WebsocketCommunicator

from common.redis_client import redis_client
from tests.helpers.live import frame_header, viewer
from tests.helpers.models import ready_model
from training import selectors, streams
from training.consumers import WINDOW, TrainingConsumer
from training.models import TrainingJob

pytestmark = [pytest.mark.django_db(transaction=True), pytest.mark.usefixtures("tracks")]

JPEG = b"\xff\xd8\xff\xe0" + bytes(2000)


@pytest.fixture(autouse=True)
def no_live_keys_of_earlier_tests():
    """Job numbers come back after the database is flushed; the live keys must not."""
    client = redis_client()
    for name in client.scan_iter("pitlane:live:*"):
        client.delete(name)


def queued_job(owner) -> TrainingJob:
    model = ready_model(owner, name=f"live-{owner.username}")
    return TrainingJob.objects.create(model=model)


async def watching(job: TrainingJob, user) -> WebsocketCommunicator:
    """A viewer of ``job``, connected, past the state it gets on connecting."""
    communicator = await viewer(f"/ws/jobs/{job.pk}/", user)
    connected, _ = await communicator.connect()
    assert connected
    assert (await communicator.receive_json_from(timeout=5))["type"] == "state"
    return communicator


async def send_frames(group: str, count: int, size: int = len(JPEG), first: int = 1) -> None:
    layer = get_channel_layer()
    for seq in range(first, first + count):
        frame = streams.frame_event(0, "spectator", JPEG[:4] + bytes(size - 4), seq=seq)
        await layer.group_send(group, streams.pack_frame(frame))


async def caught_up(communicator: WebsocketCommunicator, group: str) -> None:
    """Wait till the viewer's consumer has handled every message sent to ``group`` so far: a
    marker sent after them comes back (updates are not held for acks as frames are). A consumer
    that lags, as under a busy suite, has the channel layer drop what passes its channel's
    capacity (100, channels_redis's default), a marker too, so one is sent again till one lands.
    (``receive_nothing`` polls: a receive that times out would cancel the consumer.)"""
    layer = get_channel_layer()
    for marker in range(30):
        update = {"type": "job.update", "message": {"type": "caught-up", "marker": marker}}
        await layer.group_send(group, update)
        deadline = time.monotonic() + 2
        while time.monotonic() < deadline:
            if await communicator.receive_nothing(timeout=0.1):
                continue
            if (await communicator.receive_json_from()).get("marker") == marker:
                return
    raise TimeoutError("the viewer's consumer did not catch up with its group in 60 s")


async def test_the_owner_connects_and_gets_the_whole_state_at_once(alice):
    job = await sync_to_async(queued_job)(alice)
    communicator = await viewer(f"/ws/jobs/{job.pk}/", alice)
    connected, _ = await communicator.connect()
    assert connected
    state = await communicator.receive_json_from(timeout=5)
    await communicator.disconnect()
    assert state["type"] == "state"
    assert state["status"] == "QUEUED"
    assert state["queue_position"] == 1
    assert state["max_seconds"] == 60 * 60
    assert state["history"] == []


async def test_staff_may_watch_any_job(alice, stella):
    job = await sync_to_async(queued_job)(alice)
    communicator = await viewer(f"/ws/jobs/{job.pk}/", stella)
    connected, _ = await communicator.connect()
    assert connected
    await communicator.disconnect()


@pytest.mark.parametrize(("who", "code"), [("another racer", 4403), ("anonymous", 4401)])
async def test_another_racer_and_anonymous_are_refused(who, code, alice, bob):
    job = await sync_to_async(queued_job)(alice)
    communicator = await viewer(f"/ws/jobs/{job.pk}/", bob if who == "another racer" else None)
    connected, refused_with = await communicator.connect()
    await communicator.disconnect()
    assert not connected
    assert refused_with == code


async def test_a_job_that_does_not_exist_is_refused_like_one_of_another_racer(alice):
    communicator = await viewer("/ws/jobs/999999/", alice)
    connected, code = await communicator.connect()
    await communicator.disconnect()
    assert (connected, code) == (False, 4403)


async def test_a_bad_origin_is_refused_even_for_the_owner(alice):
    job = await sync_to_async(queued_job)(alice)
    communicator = await viewer(
        f"/ws/jobs/{job.pk}/", alice, origin=(b"origin", b"https://evil.example")
    )
    connected, code = await communicator.connect()
    # A refused socket's consumer still listens on the channel layer until the client goes:
    # disconnecting ends it here, not in the event loop's teardown, where cancelling its Redis
    # read once hung for the test's whole timeout.
    await communicator.disconnect()
    assert not connected
    assert code not in (4401, 4403)  # the origin check answered before the consumer


async def test_updates_arrive_in_the_order_they_were_sent(alice):
    job = await sync_to_async(queued_job)(alice)
    communicator = await watching(job, alice)
    group = streams.training_group(job.pk)
    layer = get_channel_layer()
    for number in range(1, 51):
        await layer.group_send(
            group, {"type": "job.update", "message": {"type": "iteration", "number": number}}
        )
    numbers = [(await communicator.receive_json_from(timeout=5))["number"] for _ in range(50)]
    await communicator.disconnect()
    assert numbers == list(range(1, 51))


async def test_frames_are_binary_with_a_header_and_each_is_released_by_an_ack(alice):
    job = await sync_to_async(queued_job)(alice)
    communicator = await watching(job, alice)
    group = streams.training_group(job.pk)

    await send_frames(group, 1)
    header, jpeg = frame_header(await communicator.receive_from(timeout=5))
    assert header["seq"] == 1 and header["view"] == "spectator" and header["worker"] == 0
    assert jpeg.startswith(b"\xff\xd8\xff")
    assert header["rendered_at"] <= time.time()

    # Another worker's frames, or another view, are not this viewer's.
    for worker, view in ((1, "spectator"), (0, "camera")):
        frame = streams.frame_event(worker, view, JPEG, seq=50)
        await get_channel_layer().group_send(group, streams.pack_frame(frame))
    assert await communicator.receive_nothing(timeout=0.3)
    await communicator.disconnect()


@pytest.mark.slow
async def test_a_slow_viewer_gets_the_newest_frame_and_never_a_backlog(alice):
    job = await sync_to_async(queued_job)(alice)
    communicator = await watching(job, alice)
    group = streams.training_group(job.pk)

    await send_frames(group, 10)  # the viewer acknowledges nothing
    first = [
        frame_header(await communicator.receive_from(timeout=5))[0]["seq"] for _ in range(WINDOW)
    ]
    assert first == [1, 2]
    assert await communicator.receive_nothing(timeout=0.3)  # no more until an ack

    tracemalloc.start()
    before, _ = tracemalloc.get_traced_memory()
    await send_frames(group, 300, size=50_000, first=11)  # 15 MB the viewer does not take
    await caught_up(communicator, group)
    after, _ = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert after - before < 2_000_000  # at most a frame or two held, not 300
    assert await communicator.receive_nothing(timeout=0.3)

    # The next frame after the flood (which a lagging consumer's layer may have cut short at its
    # capacity) is the one an ack brings: straight to the newest, everything between dropped.
    await send_frames(group, 1, first=311)
    await caught_up(communicator, group)
    await communicator.send_json_to({"type": "ack"})
    newest, _ = frame_header(await communicator.receive_from(timeout=5))
    assert newest["seq"] == 311
    await communicator.send_json_to({"type": "ack"})
    assert await communicator.receive_nothing(timeout=0.3)
    await communicator.disconnect()


async def test_viewers_register_what_they_watch_and_leave_no_registration_behind(alice):
    job = await sync_to_async(queued_job)(alice)
    stream = streams.Stream(redis_client(), streams.training_group(job.pk))
    communicator = await watching(job, alice)
    assert await sync_to_async(stream.wanted)(0) == {"spectator"}

    await communicator.send_json_to({"type": "watch", "worker": 0, "view": "camera"})
    await asyncio.sleep(0.3)
    assert await sync_to_async(stream.wanted)(0) == {"camera"}
    await communicator.send_json_to({"type": "watch", "worker": 7, "view": "camera"})
    await communicator.send_json_to({"type": "watch", "worker": 0, "view": "x-ray"})
    await asyncio.sleep(0.3)
    assert await sync_to_async(stream.wanted)(0) == {"camera"}  # a worker the job lacks, a view

    await communicator.disconnect()
    await asyncio.sleep(0.3)
    assert await sync_to_async(stream.wanted)(0) == set()  # nobody watches: no frames are made


async def test_a_viewer_who_reconnects_gets_the_newest_frame_at_once(alice):
    job = await sync_to_async(queued_job)(alice)
    group = streams.training_group(job.pk)
    stream = streams.Stream(redis_client(), group)
    frame = streams.frame_event(0, "spectator", JPEG, seq=42)
    await sync_to_async(stream.keep_frame)(streams.pack_frame(frame))

    communicator = await viewer(f"/ws/jobs/{job.pk}/", alice)
    await communicator.connect()
    assert (await communicator.receive_json_from(timeout=5))["type"] == "state"
    header, _ = frame_header(await communicator.receive_from(timeout=5))
    await communicator.disconnect()
    assert header["seq"] == 42


async def test_the_publisher_sends_the_newest_frame_and_never_blocks_the_simulation(alice):
    job = await sync_to_async(queued_job)(alice)
    group = streams.training_group(job.pk)
    communicator = await watching(job, alice)
    delivering, released = threading.Event(), threading.Event()

    class StuckPublisher(streams.FramePublisher):
        """Its deliveries wait until the test releases them: a channel layer that is slow."""

        def _deliver(self, loop, layer, frame):
            delivering.set()
            released.wait(timeout=30)
            super()._deliver(loop, layer, frame)

    def simulate() -> int:
        with StuckPublisher(redis_client(), group) as publisher:
            publisher.offer(streams.frame_event(0, "spectator", JPEG))
            assert delivering.wait(timeout=30)
            for _ in range(999):  # none of these offers waits for the stuck delivery
                publisher.offer(streams.frame_event(0, "spectator", JPEG))
            waiting = len(publisher._mailbox)
            released.set()
        return waiting

    waiting = await sync_to_async(simulate, thread_sensitive=False)()
    received = []
    while not await communicator.receive_nothing(timeout=0.5):
        received.append(frame_header(await communicator.receive_from())[0]["seq"])
        await communicator.send_json_to({"type": "ack"})
    await communicator.disconnect()
    assert waiting == 1  # the frames offered meanwhile replaced one another
    assert received == [1, 1000]  # the stuck one, then the newest: the last always goes out


async def test_status_and_iterations_from_the_trainer_reach_the_page(alice):
    job = await sync_to_async(queued_job)(alice)
    communicator = await watching(job, alice)

    def trainer_side() -> None:
        TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.IN_PROGRESS)
        job.iteration_rows.create(
            number=1,
            reward=12.5,
            completion=40.0,
            episodes=2,
            steps=90,
            wall_seconds=1.0,
            training_points=[[10.0, 30.0], [15.0, 50.0]],
            evaluation_points=[45.0],
        )
        streams.announce_training(job.pk)
        streams.announce_iteration(job.pk, 1)

    await sync_to_async(trainer_side)()
    status = await communicator.receive_json_from(timeout=5)
    iteration = await communicator.receive_json_from(timeout=5)
    await communicator.disconnect()
    assert status["type"] == "status" and status["status"] == "IN_PROGRESS"
    assert iteration == {
        **await sync_to_async(lambda: selectors.iteration_point(row=job.iteration_rows.get()))(),
        "type": "iteration",
    }
    assert iteration["training_points"] == [[10.0, 30.0], [15.0, 50.0]]


async def test_an_update_announced_while_the_viewer_connects_is_not_lost(alice, monkeypatch):
    """The worker stores and announces a new status just after the viewer's state was read: the
    viewer, already in the group, gets it next, and its page is not left behind the job."""
    job = await sync_to_async(queued_job)(alice)
    read_state = TrainingConsumer.snapshot_for

    def state_then_the_worker_moves_on(consumer, user, pk):
        state = read_state(consumer, user, pk)
        TrainingJob.objects.filter(pk=pk).update(status=TrainingJob.Status.IN_PROGRESS)
        streams.announce_training(pk)
        return state

    monkeypatch.setattr(TrainingConsumer, "snapshot_for", state_then_the_worker_moves_on)
    communicator = await watching(job, alice)
    update = await communicator.receive_json_from(timeout=5)
    await communicator.disconnect()
    assert (update["type"], update["status"]) == ("status", "IN_PROGRESS")
