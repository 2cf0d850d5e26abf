"""A machine's rollout workers share one copy of each version of the policy weights
(``rl.weights_cache``): Redis sends it once per machine, a torn or stale copy is never loaded,
and old versions and idle jobs' copies are removed. Redis is real."""

import fcntl
import multiprocessing
import os
import threading
import time

import pytest

from common.redis_client import redis_client
from rl.experience import JobChannel
from rl.weights_cache import TEMPORARY, Published, WeightsCache, weights_digest

WORKERS = 6
JOB = 987_801


def published(version: int, weights: bytes) -> Published:
    return Published(version, len(weights), weights_digest(weights))


class Fetches:
    """A ``fetch`` that hands out ``weights`` as ``version`` and counts its calls."""

    def __init__(self, version: int, weights: bytes) -> None:
        self.published, self.weights = published(version, weights), weights
        self.calls = 0

    def __call__(self) -> tuple[Published, bytes]:
        self.calls += 1
        return self.published, self.weights


@pytest.fixture
def channel():
    channel = JobChannel(redis_client(timeout=10.0), job_id=JOB)
    yield channel
    channel.client.delete(channel.policy)


def test_concurrent_workers_of_a_machine_fetch_a_version_from_redis_once_and_all_get_it(
    channel, tmp_path, monkeypatch
):
    weights = os.urandom(3_000_000)
    channel.publish(4, weights, episodes=20)
    fetched = []
    real_fetch = channel._fetch_published

    def counted_fetch():
        time.sleep(0.2)  # a slow network: the others arrive while this one fetches
        fetched.append(1)
        return real_fetch()

    monkeypatch.setattr(channel, "_fetch_published", counted_fetch)
    start = threading.Barrier(WORKERS)
    got = [None] * WORKERS

    def worker(index: int) -> None:
        start.wait()
        got[index] = channel.fetch_policy(WeightsCache(tmp_path))

    threads = [threading.Thread(target=worker, args=(index,)) for index in range(WORKERS)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len(fetched) == 1
    assert got == [(4, weights)] * WORKERS
    assert channel.fetch_policy() == (4, weights)  # without a cache, straight from Redis


def _fetch_in_a_process(directory: str, weights: bytes, log: str, results) -> None:
    def fetch():
        with open(log, "a") as calls:
            calls.write("fetched\n")
        time.sleep(0.2)
        return published(7, weights), weights

    version, data = WeightsCache(directory).weights(JOB, published(7, weights), fetch)
    results.put((version, weights_digest(data)))


def test_worker_processes_wait_for_the_one_fetch_of_another(tmp_path):
    weights = os.urandom(1_000_000)
    context = multiprocessing.get_context("fork")
    results = context.Queue()
    log = tmp_path / "fetches.log"
    processes = [
        context.Process(
            target=_fetch_in_a_process, args=(str(tmp_path / "cache"), weights, str(log), results)
        )
        for _ in range(4)
    ]
    for process in processes:
        process.start()
    answers = [results.get(timeout=30) for _ in processes]
    for process in processes:
        process.join(10)
    assert log.read_text() == "fetched\n"
    assert answers == [(7, weights_digest(weights))] * 4


def test_a_copy_torn_by_a_crash_is_never_loaded_and_is_fetched_again(tmp_path):
    weights = os.urandom(100_000)
    fetch = Fetches(3, weights)
    folder = tmp_path / f"job-{JOB}"
    folder.mkdir()
    # A writer died mid-write (its temporary file), and a machine crashed before the renamed
    # file's data reached the disk (the right name, half the bytes).
    (folder / f"{TEMPORARY}999-dead").write_bytes(weights[:50_000])
    (folder / fetch.published.file_name).write_bytes(weights[:50_000])
    assert WeightsCache(tmp_path).weights(JOB, fetch.published, fetch) == (3, weights)
    assert fetch.calls == 1
    assert sorted(path.name for path in folder.iterdir()) == [".lock", fetch.published.file_name]
    assert (folder / fetch.published.file_name).read_bytes() == weights
    # Same size, other bytes (a copy damaged in place): not loaded either.
    (folder / fetch.published.file_name).write_bytes(bytes(len(weights)))
    assert WeightsCache(tmp_path).weights(JOB, fetch.published, fetch) == (3, weights)
    assert fetch.calls == 2


def test_a_run_restarted_from_an_earlier_checkpoint_never_loads_the_old_runs_version(tmp_path):
    cache = WeightsCache(tmp_path)
    first = Fetches(5, b"the first run's version 5")
    assert cache.weights(JOB, first.published, first) == (5, b"the first run's version 5")
    again = Fetches(5, b"the new run's version 5")
    assert cache.weights(JOB, again.published, again) == (5, b"the new run's version 5")
    assert again.calls == 1
    assert cache.weights(JOB, again.published, again) == (5, b"the new run's version 5")
    assert again.calls == 1  # read from the machine's copy


def test_a_job_keeps_only_its_newest_version_and_idle_jobs_copies_are_removed(tmp_path):
    cache = WeightsCache(tmp_path, idle_job=60)
    for version in range(3):
        fetch = Fetches(version, f"version {version}".encode())
        cache.weights(JOB, fetch.published, fetch)
    assert [path.name for path in (tmp_path / f"job-{JOB}").glob("*.weights")] == [
        fetch.published.file_name
    ]
    ended = tmp_path / "job-1"
    ended.mkdir()
    (ended / "0-1-x.weights").write_bytes(b"x")
    long_ago = time.time() - 120
    os.utime(ended, (long_ago, long_ago))
    fetch = Fetches(3, b"version 3")
    cache.weights(JOB, fetch.published, fetch)
    assert not ended.exists()


def test_a_worker_that_waits_too_long_for_the_lock_fetches_for_itself(tmp_path):
    fetch = Fetches(2, b"version 2")
    folder = tmp_path / f"job-{JOB}"
    folder.mkdir()
    with open(folder / ".lock", "a+b") as held:  # a worker stopped while it held the lock
        fcntl.flock(held, fcntl.LOCK_EX)
        assert WeightsCache(tmp_path, patience=0.05).weights(JOB, fetch.published, fetch) == (
            2,
            b"version 2",
        )
    assert fetch.calls == 1
    assert not list(folder.glob("*.weights"))  # not stored without the lock


def test_a_cache_it_cannot_write_costs_only_the_cache(tmp_path):
    blocked = tmp_path / "a file, not a folder"
    blocked.write_text("")
    fetch = Fetches(1, b"version 1")
    assert WeightsCache(blocked / "weights").weights(JOB, fetch.published, fetch) == (
        1,
        b"version 1",
    )
    assert fetch.calls == 1


def test_rollout_workers_of_one_machine_drive_with_weights_fetched_once(channel, monkeypatch):
    from types import SimpleNamespace

    from jobs.rollouts import Printed, _drive
    from tests.helpers.rollouts import ScriptedCars, Unwatched

    fetched = []  # the weights' trips from Redis
    hmget = channel.client.hmget
    monkeypatch.setattr(
        channel.client,
        "hmget",
        lambda name, *keys: (
            (fetched.append(1) if "weights" in keys else None) or hmget(name, *keys)
        ),
    )
    channel.start(attempt=1)
    channel.publish(0, b"weights 0", episodes=100)
    job = SimpleNamespace(model=SimpleNamespace(algorithm="clipped_ppo"))
    for worker in range(2):  # each drives one episode with version 0, then the racer stops
        sandbox = ScriptedCars({1: channel.request_stop})
        assert _drive(sandbox, channel, channel.join(1), job, worker, Unwatched(), Printed())
        assert sandbox.loads == [(0, 0)]
        channel.client.hset(channel.control, "stop", 0)
    assert len(fetched) == 1
    channel.client.delete(channel.experience, channel.counts, channel.control, channel.log)
