"""Shared fixtures: named racers, a staff member, and the real processes of the stack."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest
import redis
from channels.layers import channel_layers
from django.conf import settings
from django.contrib.auth.models import User

from common.health import live_workers
from common.redis_client import redis_client
from console.supervisor import worker_pools
from tests.helpers.accounts import racer
from tests.services import (
    SUITE_REDIS,
    RedisServer,
    ServiceProcess,
    daphne_started,
    free_port,
    python_module,
    service_env,
    wait_for,
)

TRAINERS = 2  # the suite's training worker's processes (celery_worker_process)
TESTS = Path(__file__).parent
BROWSER_TESTS = TESTS / "browser"


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist names each test's group from its marker
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Browser tests are marked, and run last: the slowest, and the ones that need everything.
    Tests that take the ``tensorflow`` fixture are marked too, and those that need the suite's
    Celery worker are slow (``make test-quick`` leaves them out: TensorFlow takes seconds to
    load, the worker to start, and its tasks drive the simulator).

    Where the suite runs in several processes (``make test``: pytest-xdist's ``-n 2 --dist
    loadgroup``), the tests that share a costly session's service run in one process, so that it
    is started once: the cluster's own machines first (the longest test, beside everything
    else), then the suite's Celery workers' (browser tests among them), then the browser's. The
    others spread a module at a time, a module's fixtures and caches set up once, and
    TensorFlow's tests all in one process, which alone loads it. (Until 2026-11-30, under pytest
    9.2, the groups never reached the scheduler, pytest-dev/pytest-xdist#1386: every test spread
    on its own, both processes started the Celery workers, and both ``manage.py runconsole``.)"""
    rank: dict[str, int] = {}
    for item in items:
        fixtures = getattr(item, "fixturenames", ())
        if item.path.is_relative_to(BROWSER_TESTS):
            item.add_marker(pytest.mark.browser)
        if "tensorflow" in fixtures:
            item.add_marker(pytest.mark.tensorflow)
        if "celery_worker_process" in fixtures:
            item.add_marker(pytest.mark.slow)
        group = _process_group(item, fixtures)
        item.add_marker(pytest.mark.xdist_group(group))
        rank[item.nodeid] = _rank(item, group)
    items.sort(key=lambda item: rank[item.nodeid])


GROUPS = ("cluster", "celery", "browser")  # in the order they start


def _process_group(item: pytest.Item, fixtures) -> str:
    if item.get_closest_marker("cluster"):
        return "cluster"
    if "celery_worker_process" in fixtures:
        return "celery"
    if item.path.is_relative_to(BROWSER_TESTS):
        return "browser"
    if "tensorflow" in fixtures:
        return "tensorflow"
    return item.path.relative_to(TESTS).with_suffix("").as_posix()  # its module's


def _rank(item: pytest.Item, group: str) -> float:
    """Browser tests last when the suite runs in one process; in several, the groups first. A
    test marked ``late`` comes last in its group: the browser journey, the longest browser test,
    then runs beside the other process's short tests instead of the Celery group's trainings
    (which it did, at 82 s, in the suite's run at 54a4eab, against 36 s alone)."""
    late = 0.5 if item.get_closest_marker("late") else 0.0
    if os.environ.get("PYTEST_XDIST_WORKER"):  # a worker's collection: the scheduler's order
        return (GROUPS.index(group) if group in GROUPS else len(GROUPS)) + late
    return (1 if item.path.is_relative_to(BROWSER_TESTS) else 0) + late


@pytest.fixture(scope="session", autouse=True)
def _torch_threads_shared_by_the_processes() -> None:
    """In several test processes, each one's own PyTorch work (updates, policies, exports) takes
    its share of the cores: two processes each running a thread a core wait at each other's
    barriers (a SAC update test took 17 s in one run of ``make test-quick``, 3 s in another). The
    workers started by the tests size their own threads."""
    processes = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if processes > 1:
        import torch

        torch.set_num_threads(max(1, (os.cpu_count() or 1) // processes))


@pytest.fixture(scope="session")
def tensorflow():
    """TensorFlow, loaded once: the car's graph is run in it, as the car runs it."""
    import tensorflow

    return tensorflow


@pytest.fixture(scope="module")
def s3_server() -> Iterator[str]:
    """moto's S3 API on a free local port; its endpoint URL (any keys are taken)."""
    from moto.server import ThreadedMotoServer

    port = free_port()
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=port, verbose=False)
    server.start()
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.stop()


@pytest.fixture(autouse=True)
def _fresh_channel_layers() -> Iterator[None]:
    """Every test gets its own channel layer: channels_redis's layer keeps asyncio locks of the
    event loop that first used them, and each async test runs in a loop of its own, so a receive
    lock left held when an earlier test's loop closed stopped a later test's consumer
    ("... is bound to a different event loop"; the full suite, 2026-11-27)."""
    yield
    channel_layers.backends.clear()


@pytest.fixture(autouse=True)
def _fresh_rate_limits() -> Iterator[None]:
    """Every test starts with no attempts counted: the counters live in the suite's Redis, and
    racers' ids repeat from test to test."""
    yield
    try:
        client = redis_client()
        keys = list(client.scan_iter(match=f"{settings.CACHES['default']['KEY_PREFIX']}:*:rl:*"))
        if keys:
            client.delete(*keys)
    except redis.RedisError:  # a test that stopped the suite's Redis has nothing to clear
        return


@pytest.fixture
def own_storage(settings, tmp_path) -> Path:
    """Storage of the test's own, for a test that counts every stored file: the suite's Celery
    workers share the process's storage, and a job a Celery test left training writes its files
    there while later tests run (CI, 2026-11-29: a model's four files appeared during an import
    test that counted them). Its folder."""
    location = tmp_path / "storage"
    default = settings.STORAGES["default"]
    settings.STORAGES = {
        **settings.STORAGES,
        "default": {**default, "OPTIONS": {**default.get("OPTIONS", {}), "location": location}},
    }
    settings.MEDIA_ROOT = location
    return location


@pytest.fixture
def alice(db) -> User:
    return racer("alice")


@pytest.fixture
def bob(db) -> User:
    return racer("bob")


@pytest.fixture
def stella(db) -> User:
    """League staff."""
    return racer("stella", is_staff=True)


@pytest.fixture
def tracks(db):
    from training.services import tracks_sync

    return tracks_sync()


@pytest.fixture(scope="session")
def test_database(django_db_setup, django_db_blocker) -> str:
    return settings.DATABASES["default"]["NAME"]


@pytest.fixture(scope="session")
def logs_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("logs")


class WorkerPools:
    """The Celery workers `make run` starts, one per queue (console.supervisor.worker_pools)."""

    def __init__(self, workers: list[ServiceProcess]) -> None:
        self.workers = workers

    @property
    def pids(self) -> set[int]:
        return {worker.pid for worker in self.workers}

    def ensure_running(self) -> None:
        for worker in self.workers:
            worker.ensure_running()

    def stop(self) -> None:
        for worker in self.workers:
            worker.stop()


@pytest.fixture(scope="session")
def celery_worker_process(test_database, logs_dir) -> Iterator[WorkerPools]:
    """Real Celery worker processes, one per queue, as `make run` starts them: two trainers (the
    suite's tests may leave a job training), three simulation processes, one re-scoring."""
    pools = WorkerPools(
        [
            ServiceProcess(
                python_module("celery", *pool.arguments(), "--without-mingle", "--without-gossip"),
                # One PyTorch thread a trainer, as the cluster's machines have: the suite keeps
                # both cores busy, where a second thread only waits at each update's barriers.
                env={
                    **service_env(test_database),
                    "PITLANE_TRAINERS": str(TRAINERS),
                    "PITLANE_TRAINER_THREADS": "1",
                },
                log=logs_dir / f"celery-{pool.queue}.log",
            )
            for pool in worker_pools(trainers=TRAINERS, simulations=3, prefix="test-")
        ]
    )

    def reported() -> bool:
        pools.ensure_running()
        return pools.pids <= {w["pid"] for w in live_workers(redis_client())}

    try:
        wait_for(reported, "the Celery workers to report in")
        yield pools
    finally:
        pools.stop()


@pytest.fixture(scope="session")
def suite_redis(pytestconfig) -> RedisServer:
    """The suite's own Redis (``tests.services``), for a test that restarts it."""
    return pytestconfig.stash[SUITE_REDIS]


@pytest.fixture(scope="session")
def daphne_server(test_database, logs_dir) -> Iterator[str]:
    """Daphne serving console.asgi on a free port; the base URL."""
    server, port = daphne_started(test_database, logs_dir / "daphne.log")
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.stop()
