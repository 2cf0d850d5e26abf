"""Staff import a club's models from DeepRacer for Cloud's bucket on the console's page, for
themselves or a racer; racers cannot, and a wrong place or racer is said in words."""

from __future__ import annotations

import boto3
import pytest
from django.urls import reverse

from tests.helpers.archives import CHECKED_IMPORT, deepracer_export, drfc_layout
from training.models import RLModel

pytestmark = CHECKED_IMPORT
PAGE = reverse("archives:model-import-bucket")


@pytest.fixture
def bucket(s3_server, settings):
    settings.PITLANE_DRFC_S3 = {
        "endpoint_url": s3_server,
        "region_name": "us-east-1",
        "aws_access_key_id": "minio",
        "aws_secret_access_key": "miniostorage",
    }
    s3 = boto3.client("s3", **settings.PITLANE_DRFC_S3)
    s3.create_bucket(Bucket="club")
    for path, data in drfc_layout(deepracer_export()).items():
        s3.put_object(Bucket="club", Key=f"rl-deepracer-sagemaker/{path}", Body=data)
    return "s3://club/rl-deepracer-sagemaker"


def test_staff_import_a_racers_model_from_the_bucket(client, alice, stella, tracks, bucket):
    client.force_login(alice)
    assert client.get(PAGE).status_code == 302  # to the admin's sign-in: staff only
    assert "DeepRacer for Cloud's bucket" not in client.get(reverse("archives:model-import")).text
    client.force_login(stella)
    assert "DeepRacer for Cloud's bucket" in client.get(reverse("archives:model-import")).text

    nowhere = client.post(PAGE, {"url": "club/rl-deepracer-sagemaker", "racer": "alice"})
    assert nowhere.status_code == 400
    assert "give s3://&lt;bucket&gt;/&lt;model prefix&gt;" in nowhere.text
    nobody = client.post(PAGE, {"url": bucket, "racer": "nobody"})
    assert "No racer logs in as" in nobody.text
    empty = client.post(PAGE, {"url": "s3://club/not-there", "racer": "alice"})
    assert "Nothing is stored under s3://club/not-there" in empty.text

    done = client.post(
        PAGE, {"url": bucket, "name": "from-the-club", "racer": "alice"}, follow=True
    )
    model = RLModel.objects.get(owner=alice)
    assert model.name == "from-the-club"
    # its training queued, or begun already by the suite's worker
    assert model.status in (RLModel.Status.QUEUED, RLModel.Status.TRAINING)
    assert "(from s3://club/rl-deepracer-sagemaker for alice)" in done.text
