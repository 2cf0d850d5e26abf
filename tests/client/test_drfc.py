"""Which files of a DeepRacer for Cloud model's prefix `pitlane import s3://...` takes: the best
and the last checkpoint as deepracer_checkpoints.json names them, else rl_coach's latest, else
the highest number, as dr-upload-model and the import choose (a real S3 API: moto's server)."""

from __future__ import annotations

import io
import json
import tarfile

import boto3
import pytest
from pitlane_client import drfc

STEPS = ("1_Step-100.ckpt", "2_Step-200.ckpt", "3_Step-300.ckpt")
BEST_AND_LAST = {"best_checkpoint": {"name": STEPS[0]}, "last_checkpoint": {"name": STEPS[1]}}


@pytest.fixture
def s3(s3_server, monkeypatch):
    for name, value in (("AWS_ACCESS_KEY_ID", "minio"), ("AWS_SECRET_ACCESS_KEY", "minio123")):
        monkeypatch.setenv(name, value)
    client = boto3.client("s3", endpoint_url=s3_server, region_name="us-east-1")
    client.create_bucket(Bucket="drfc")
    return client


@pytest.mark.parametrize(
    ("pointers", "taken"),
    [
        ({"deepracer_checkpoints.json": json.dumps(BEST_AND_LAST)}, STEPS[:2]),
        (
            {
                "deepracer_checkpoints.json": '{"best_checkpoint": "x"}',
                ".coach_checkpoint": STEPS[1],
            },
            STEPS[1:2],
        ),
        ({"deepracer_checkpoints.json": "[1]"}, STEPS[2:]),  # not DeepRacer's: the highest
        ({}, STEPS[2:]),
    ],
    ids=["best and last", "rl_coach's latest", "unreadable pointer", "no pointer"],
)
def test_the_checkpoints_taken_are_those_deepracer_names(s3, pointers, taken, request):
    prefix = request.node.callspec.id.replace(" ", "-").replace("'", "")
    files = {"model/model_metadata.json": "{}", **{f"model/{k}": v for k, v in pointers.items()}}
    for step in STEPS:
        files |= {f"model/{step}.index": "i", f"model/{step}.data-00000-of-00001": "d"}
        files[f"model/{step}.meta"] = "TensorFlow's graph: not needed"
    for path, text in files.items():
        s3.put_object(Bucket="drfc", Key=f"{prefix}/{path}", Body=text.encode())
    out = io.BytesIO()
    packed = drfc.pack(s3, f"s3://drfc/{prefix}", out)
    out.seek(0)
    with tarfile.open(fileobj=out) as tar:
        names = tar.getnames()
    assert sorted(n for n in names if n.endswith(".index")) == [f"model/{s}.index" for s in taken]
    assert not any(n.endswith(".meta") for n in names) and packed.size > 0
