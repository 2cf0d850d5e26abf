"""Videos and downloads answer byte ranges, as a video element asks for them to seek (206 with the
bytes asked for, 416 past the end, 200 with ``Accept-Ranges`` without a range), after the same
ownership checks."""

from __future__ import annotations

import pytest
from django.urls import reverse

from racing.models import Submission
from tests.helpers.analysis import untrained
from tests.helpers.league import event
from training import artifacts
from training.models import EvaluationJob

pytestmark = pytest.mark.django_db

VIDEO = bytes(range(256)) * 40  # 10,240 bytes, each offset telling which byte it is


@pytest.fixture
def recorded(alice, tracks):
    """A model of alice's with a training metrics file and an evaluation whose video is stored."""
    model = untrained(alice, "recorded")
    artifacts.save(model, artifacts.TRAINING_METRICS, VIDEO)
    evaluation = EvaluationJob.objects.create(model=model, track=model.track, status="COMPLETED")
    artifacts.save(
        model, artifacts.evaluation_prefix(evaluation) + artifacts.EVALUATION_VIDEO, VIDEO
    )
    return evaluation


def body(response) -> bytes:
    return b"".join(response.streaming_content)


def urls(evaluation: EvaluationJob) -> dict[str, str]:
    model = evaluation.model
    return {
        "video": reverse(
            "training:evaluation-file", args=[model.pk, evaluation.pk, artifacts.EVALUATION_VIDEO]
        ),
        "download": reverse("training:model-file", args=[model.pk, artifacts.TRAINING_METRICS]),
    }


@pytest.mark.parametrize("which", ["video", "download"])
def test_it_answers_a_range_with_exactly_those_bytes(client, alice, recorded, which):
    client.force_login(alice)
    url = urls(recorded)[which]

    middle = client.get(url, headers={"Range": "bytes=1000-1999"})
    assert middle.status_code == 206
    assert body(middle) == VIDEO[1000:2000]
    assert middle["Content-Range"] == f"bytes 1000-1999/{len(VIDEO)}"
    assert middle["Content-Length"] == "1000"
    assert middle["Accept-Ranges"] == "bytes"

    rest = client.get(url, headers={"Range": "bytes=10000-"})  # a seek near the end
    assert (rest.status_code, body(rest)) == (206, VIDEO[10000:])
    last = client.get(url, headers={"Range": "bytes=-5"})
    assert (last.status_code, body(last)) == (206, VIDEO[-5:])


@pytest.mark.parametrize("which", ["video", "download"])
def test_it_refuses_a_range_past_the_end_and_sends_all_without_one(client, alice, recorded, which):
    client.force_login(alice)
    url = urls(recorded)[which]

    past = client.get(url, headers={"Range": f"bytes={len(VIDEO)}-"})
    assert past.status_code == 416
    assert past["Content-Range"] == f"bytes */{len(VIDEO)}"

    whole = client.get(url)
    assert whole.status_code == 200 and whole["Accept-Ranges"] == "bytes"
    assert whole["Content-Length"] == str(len(VIDEO)) and body(whole) == VIDEO
    several = client.get(url, headers={"Range": "bytes=0-1,5-6"})  # answered whole, as allowed
    assert (several.status_code, body(several)) == (200, VIDEO)


def test_a_range_keeps_the_videos_type_and_disposition_and_head_sends_no_body(
    client, alice, recorded
):
    client.force_login(alice)
    video = client.get(urls(recorded)["video"], headers={"Range": "bytes=0-0"})
    assert video["Content-Type"] == "video/webm"
    assert video["Content-Disposition"].startswith("inline; ")
    download = client.get(urls(recorded)["download"], headers={"Range": "bytes=0-0"})
    assert download["Content-Disposition"].startswith("attachment; ")

    head = client.head(urls(recorded)["video"], headers={"Range": "bytes=0-99"})
    assert head.status_code == 206 and head["Content-Length"] == "100"
    assert head["Content-Range"] == f"bytes 0-99/{len(VIDEO)}" and head.content == b""


def test_another_racer_gets_no_range_of_the_video(client, bob, recorded):
    client.force_login(bob)
    for url in urls(recorded).values():
        assert client.get(url, headers={"Range": "bytes=0-9"}).status_code == 404


def test_a_race_video_answers_a_range(client, alice, recorded):
    submission = Submission.objects.create(
        event=event(),
        racer=alice,
        model_name="recorded",
        video=artifacts.path(
            recorded.model, artifacts.evaluation_prefix(recorded) + artifacts.EVALUATION_VIDEO
        ),
    )
    client.force_login(alice)
    url = reverse("racing:submission-video", args=[submission.pk])
    response = client.get(url, headers={"Range": "bytes=256-511"})
    assert (response.status_code, body(response)) == (206, VIDEO[256:512])
    assert response["Content-Type"] == "video/webm"
