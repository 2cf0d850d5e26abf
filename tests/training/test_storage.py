"""A model's files in storage: the same suite against local disk and against a real S3 API (moto's
server, reached through boto3 as a bucket is), downloads only for the owner, and delete leaving
nothing behind."""

from __future__ import annotations

import urllib.request
from urllib.parse import parse_qs, urlsplit

import boto3
import pytest
from django.core.files.storage import default_storage
from django.urls import reverse

from tests.helpers.models import trained_model
from training import artifacts, services
from training.models import EvaluationJob, RLModel, TrainingJob

pytestmark = pytest.mark.django_db

BUCKET = "pitlane-test-artifacts"


@pytest.fixture
def bucket(s3_server, settings, monkeypatch):
    """Artifacts in an S3 bucket, configured as production configures one; a boto3 client for
    looking at the bucket directly."""
    for name, value in (
        ("AWS_ACCESS_KEY_ID", "testing"),
        ("AWS_SECRET_ACCESS_KEY", "testing"),
        ("AWS_DEFAULT_REGION", "us-east-1"),
    ):
        monkeypatch.setenv(name, value)
    client = boto3.client("s3", endpoint_url=s3_server, region_name="us-east-1")
    client.create_bucket(Bucket=BUCKET)
    settings.STORAGES = {
        **settings.STORAGES,
        "default": {
            "BACKEND": "storages.backends.s3.S3Storage",
            "OPTIONS": {
                "bucket_name": BUCKET,
                "region_name": "us-east-1",
                "endpoint_url": s3_server,
                "default_acl": None,
                "querystring_auth": True,
                "querystring_expire": 300,
                "signature_version": "s3v4",
                "file_overwrite": True,
            },
        },
    }
    yield client
    for item in client.list_objects_v2(Bucket=BUCKET).get("Contents", []):
        client.delete_object(Bucket=BUCKET, Key=item["Key"])
    client.delete_bucket(Bucket=BUCKET)


def keys(client, prefix: str) -> list[str]:
    listing = client.list_objects_v2(Bucket=BUCKET, Prefix=prefix)
    return sorted(item["Key"] for item in listing.get("Contents", []))


def test_a_models_files_live_under_its_prefix_in_the_bucket(alice, tracks, bucket):
    model = trained_model(alice, "in-the-bucket")
    assert type(default_storage._wrapped).__name__ == "S3Storage"
    assert keys(bucket, f"models/{model.pk}/") == [
        f"models/{model.pk}/{name}"
        for name in (
            "checkpoints/iteration-1.safetensors",
            "hyperparameters.json",
            "model_metadata.json",
            "reward_function.py",
            "training_params.yaml",
        )
    ]
    artifacts.save(model, "metrics/training_metrics.json", '{"metrics": []}')
    artifacts.save(model, "metrics/training_metrics.json", '{"metrics": [1]}')  # replaced
    assert artifacts.read(artifacts.path(model, "metrics/training_metrics.json")) == (
        b'{"metrics": [1]}'
    )
    body = bucket.get_object(Bucket=BUCKET, Key=f"models/{model.pk}/reward_function.py")["Body"]
    assert body.read().decode() == model.reward_function


@pytest.mark.slow
def test_downloads_from_a_bucket_are_short_lived_presigned_urls_for_the_owner(
    alice, bob, tracks, bucket, client
):
    model = trained_model(alice, "presigned")
    artifacts.save(model, "metrics/training_metrics.json", '{"metrics": []}')
    url = reverse("training:model-file", args=[model.pk, "metrics/training_metrics.json"])

    client.force_login(bob)  # another racer can neither list the files nor get a URL for one
    assert client.get(reverse("training:model-detail", args=[model.pk])).status_code == 404
    assert client.get(url).status_code == 404
    assert client.get(reverse("archives:model-export-virtual", args=[model.pk])).status_code == 404

    client.force_login(alice)
    response = client.get(url)
    assert response.status_code == 302
    signed = urlsplit(response["Location"])
    query = parse_qs(signed.query)
    assert signed.path == f"/{BUCKET}/models/{model.pk}/metrics/training_metrics.json"
    assert query["X-Amz-Expires"] == ["300"]
    assert "attachment" in query["response-content-disposition"][0]
    with urllib.request.urlopen(response["Location"]) as answer:  # moto, on this machine
        assert answer.read() == b'{"metrics": []}'

    export = client.get(reverse("archives:model-export-virtual", args=[model.pk]))
    assert export.status_code == 302
    assert f"/models/{model.pk}/exports/" in export["Location"]


@pytest.mark.slow
def test_deleting_a_model_leaves_nothing_in_the_bucket(alice, tracks, bucket, client):
    model = trained_model(alice, "to-delete")
    other = trained_model(alice, "to-keep")
    artifacts.save(model, "evaluations/1/video.webm", b"\x1a\x45\xdf\xa3")
    client.force_login(alice)
    client.get(reverse("archives:model-export-virtual", args=[model.pk]))
    assert len(keys(bucket, f"models/{model.pk}/")) == 7

    response = client.post(reverse("training:model-delete", args=[model.pk]))
    assert response.status_code == 302
    assert keys(bucket, f"models/{model.pk}/") == []
    assert not RLModel.objects.filter(pk=model.pk).exists()
    assert not TrainingJob.objects.filter(model_id=model.pk).exists()
    assert len(keys(bucket, f"models/{other.pk}/")) == 5  # another model's files stay


def test_delete_is_refused_while_the_model_is_busy_and_for_another_racer(
    alice, bob, tracks, client, tmp_path
):
    model = trained_model(alice, "busy")
    RLModel.objects.filter(pk=model.pk).update(status=RLModel.Status.EVALUATING)
    url = reverse("training:model-delete", args=[model.pk])
    client.force_login(bob)
    assert client.get(url).status_code == 404
    assert client.post(url).status_code == 404

    client.force_login(alice)
    page = client.post(url, follow=True).text
    assert "it can be deleted once it is ready" in page
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.EVALUATING
    assert default_storage.exists(artifacts.path(model, "model_metadata.json"))


def test_deleting_on_local_disk_removes_the_models_folder(alice, tracks, client, settings):
    model = trained_model(alice, "local")
    EvaluationJob.objects.create(model=model, track=model.track, status="COMPLETED")
    artifacts.save(model, "evaluations/1/metrics/evaluation_metrics.json", "{}")
    folder = settings.MEDIA_ROOT / "models" / str(model.pk)
    assert folder.is_dir()
    client.force_login(alice)
    confirm = client.get(reverse("training:model-delete", args=[model.pk]))
    assert "cannot be undone" in confirm.text
    stored = [path for path in folder.rglob("*") if path.is_file()]
    assert len(stored) >= 6
    assert services.model_delete(model=model) == len(stored)
    assert not folder.exists()
    assert not EvaluationJob.objects.filter(model_id=model.pk).exists()
