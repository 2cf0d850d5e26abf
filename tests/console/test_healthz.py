import json

import pytest
from django.urls import reverse

from common.health import KEY_PREFIX
from common.redis_client import redis_client
from tests.services import RedisServer, wait_for

pytestmark = pytest.mark.django_db


@pytest.fixture
def client(client, django_user_model):
    """Staff, who read what /healthz checked; anyone else reads up or down alone."""
    client.force_login(django_user_model.objects.create_user("ops", is_staff=True))
    return client


def healthz_without_workers(client, settings, tmp_path):
    """/healthz's answer on a Redis no worker reports to."""
    redis_server = RedisServer(tmp_path / "redis")
    settings.REDIS_URL = redis_server.url
    try:
        return client.get(reverse("healthz"))
    finally:
        redis_server.stop()


def test_anyone_else_reads_up_or_down_alone(client, settings, tmp_path):
    client.logout()
    response = healthz_without_workers(client, settings, tmp_path)
    assert (response.status_code, response.json()) == (503, {"status": "down"})


def test_healthz_is_200_when_the_database_redis_and_a_worker_are_up(client, celery_worker_process):
    response = client.get(reverse("healthz"))
    assert response.status_code == 200
    body = response.json()
    assert body["status"] == "ok"
    assert body["down"] == []
    assert set(body["checks"]) == {"database", "redis", "workers"}
    workers = body["checks"]["workers"]["workers"]
    assert {"simulation", "training", "rescoring"} <= {q for w in workers for q in w["queues"]}


def test_healthz_is_503_naming_redis_when_redis_is_stopped(client, settings, tmp_path):
    redis_server = RedisServer(tmp_path / "redis")
    settings.REDIS_URL = redis_server.url
    assert client.get(reverse("healthz")).json()["checks"]["redis"]["ok"] is True

    redis_server.stop()
    response = client.get(reverse("healthz"))
    assert response.status_code == 503
    body = response.json()
    assert body["status"] == "down"
    assert "redis" in body["down"]
    assert body["checks"]["redis"]["error"].startswith("cannot reach Redis")
    assert body["checks"]["database"]["ok"] is True


def test_healthz_is_503_naming_the_workers_when_none_runs(client, settings, tmp_path):
    response = healthz_without_workers(client, settings, tmp_path)
    assert response.status_code == 503
    assert response.json()["down"] == ["workers"]
    assert response.json()["checks"]["workers"]["error"] == "no Celery worker is running"


def test_healthz_is_never_cached(client):
    assert "no-cache" in client.get(reverse("healthz"))["Cache-Control"]


def test_a_worker_reports_that_its_sandbox_holds(client, celery_worker_process):
    def sandbox_reported() -> bool:
        workers = client.get(reverse("healthz")).json()["checks"]["workers"]["workers"]
        return any((w.get("sandbox") or {}).get("ok") for w in workers)

    wait_for(sandbox_reported, "the worker's sandbox self-test", timeout=30)
    workers = client.get(reverse("healthz")).json()["checks"]["workers"]["workers"]
    # Each pool's worker tests its own sandbox: one may still be checking when another has held.
    reported = [w["sandbox"] for w in workers if (w.get("sandbox") or {}).get("ok")]
    assert reported and all("held" in sandbox["detail"] for sandbox in reported)


def test_healthz_is_503_when_no_workers_sandbox_holds(client, settings, tmp_path):
    redis_server = RedisServer(tmp_path / "redis")
    settings.REDIS_URL = redis_server.url
    record = {
        "hostname": "unsafe@box",
        "pid": 1,
        "queues": ["rescoring", "simulation", "training"],
        "started_at": 0,
        "sandbox": {"ok": False, "detail": "sealed code could read a file"},
    }
    try:
        redis_client().set(KEY_PREFIX + "unsafe@box", json.dumps(record), ex=60)
        response = client.get(reverse("healthz"))
    finally:
        redis_server.stop()
    assert response.status_code == 503
    assert response.json()["checks"]["workers"]["error"] == (
        "no worker can run racers' code safely: its sandbox self-test failed "
        "(sealed code could read a file)"
    )
