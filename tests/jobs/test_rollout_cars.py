"""A rollout worker whose sandbox drives several cars (``jobs.rollouts._drive``): each episode
goes to the buffer as its car ends it, no more are started than the trainer wants of a version,
and the weights change only while no car drives, so no episode mixes two versions. The sandbox
here is a stand-in that ends the cars' episodes in a scripted order; Redis is real."""

import time
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import msgpack
import pytest

from common.redis_client import redis_client
from jobs.rollouts import Printed, _drive, _where, cars_for
from rl import hyperparameters as hp
from rl.experience import JobChannel
from sandbox import SandboxFailure
from tests.helpers.rollouts import ScriptedCars, Unwatched


@pytest.fixture
def channel():
    channel = JobChannel(redis_client(), job_id=987_701)
    channel.start(attempt=1)
    yield channel
    channel.client.delete(
        channel.experience,
        channel.counts,
        channel.control,
        channel.policy,
        channel.log,
        channel.evaluation,
        channel.reserved,
    )


def test_a_worker_of_several_cars_drives_each_version_its_share_and_no_episode_mixes_two(
    channel,
):
    channel.publish(0, b"weights 0", episodes=5)

    def another_worker_completes_version_1() -> None:
        for _ in range(3):  # while this worker's other two cars still drive with version 1
            channel.push_episode(msgpack.packb({"version": 1, "car": "another's"}), version=1)
        channel.publish(2, b"weights 2", episodes=3)

    sandbox = ScriptedCars(
        {
            5: lambda: channel.publish(1, b"weights 1", episodes=4),  # the trainer has its 5
            6: another_worker_completes_version_1,
            11: channel.request_stop,  # the racer stops the job as version 2's third ends
        }
    )
    job = SimpleNamespace(model=SimpleNamespace(algorithm="clipped_ppo"))
    why = _drive(sandbox, channel, channel.join(1), job, 0, Unwatched(), Printed())
    assert why == "the training ended"
    # Version 0: five episodes wanted, five started on three cars. Version 1: four wanted,
    # three started (a car each); once another worker's pushes made four, none more, and the
    # two under way ended with version 1. Version 2 loaded only then.
    assert sandbox.started == {0: 5, 1: 3, 2: 3}
    assert sandbox.loads == [(0, 0), (1, 0), (2, 0)]  # never with a car driving
    pushed = [msgpack.unpackb(payload) for payload in channel.pop_episodes(limit=100)]
    ours = [episode["version"] for episode in pushed if episode["car"] != "another's"]
    assert ours == sandbox.ended == [0] * 5 + [1] * 3 + [2] * 3  # each as it ended
    counts = {
        int(version): int(count)
        for version, count in channel.client.hgetall(channel.counts).items()
    }
    assert counts == {0: 5, 1: 6, 2: 3}


def test_two_workers_of_several_cars_start_no_more_episodes_of_a_version_than_wanted(channel):
    wanted, versions = 20, 3
    fleets = [ScriptedCars({}, cars=8, pause=0.002) for _ in range(2)]
    job = SimpleNamespace(model=SimpleNamespace(algorithm="clipped_ppo"))
    run = channel.join(1)
    channel.publish(0, b"weights 0", episodes=wanted)

    def drive(worker: int) -> str:
        own = JobChannel(redis_client(), channel.job_id)  # as a worker's process has its own
        return _drive(fleets[worker], own, run, job, worker, Unwatched(), Printed())

    def learn() -> None:  # the trainer: the next version once it has this one's episodes
        given_up = time.monotonic() + 60
        try:
            for version in range(versions):
                if version:
                    channel.publish(version, b"weights %d" % version, episodes=wanted)
                while int(channel.client.hget(channel.counts, str(version)) or 0) < wanted:
                    assert time.monotonic() < given_up, f"version {version} never had {wanted}"
                    time.sleep(0.01)
        finally:
            channel.request_stop()  # the workers stop whatever happened

    with ThreadPoolExecutor(3) as pool:
        trainer = pool.submit(learn)
        workers = [pool.submit(drive, worker) for worker in range(2)]
        trainer.result(timeout=120)
        assert [worker.result(timeout=30) for worker in workers] == ["the training ended"] * 2
    started = {
        version: sum(fleet.started.get(version, 0) for fleet in fleets)
        for version in range(versions)
    }
    # Both workers drove each version (eight cars each, twenty wanted), and between them
    # started exactly the episodes wanted: none the trainer would drop.
    assert all(sum(fleet.started.values()) > 0 for fleet in fleets)
    assert started == {version: wanted for version in range(versions)}


def test_a_worker_that_replaces_one_that_died_driving_may_drive_what_that_one_had_reserved(
    channel,
):
    channel.publish(0, b"weights 0", episodes=4)
    assert channel.episodes_reserve(0, 0, 3) == 3  # worker 1's first task: it died driving them
    sandbox = ScriptedCars({1: channel.request_stop})
    job = SimpleNamespace(model=SimpleNamespace(algorithm="clipped_ppo"))
    _drive(sandbox, channel, channel.join(1), job, 0, Unwatched(), Printed())
    assert sandbox.started == {0: 3}  # its three cars at once, not the one left unreserved


def test_a_sac_worker_drives_one_car_and_a_ppo_worker_the_cars_set(settings):
    settings.PITLANE_CARS_PER_WORKER = 8
    assert (cars_for(hp.SAC), cars_for(hp.PPO)) == (1, 8)


def test_a_reward_function_that_failed_in_one_of_several_cars_names_the_car():
    failure = SandboxFailure("exception", "KeyError: 'missing'", line=4, step=3, car=1)
    assert _where(failure, worker=0) == "(worker 1, car 2)"
    alone = SandboxFailure("exception", "KeyError: 'missing'", line=4, step=3)
    assert _where(alone, worker=0) == "(worker 1)"  # a worker of one car says no more
