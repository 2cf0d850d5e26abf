"""The training clock: one origin (the trainer's ``training_seconds``, measured at ``clock_at``)
from which the model page, the model list, the live stream and the quota all read the time used,
so that they agree to the second; it stops when the racer asks to stop, and at the time limit."""

import re
from datetime import timedelta
from unittest import mock

import pytest
from django.urls import reverse
from django.utils import timezone

from tests.helpers.training import training_job
from training import leases, selectors
from training.models import TrainingJob
from training.services import training_stop

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


def at(moment):
    """The server's clock stopped at ``moment``."""
    return mock.patch("django.utils.timezone.now", return_value=moment)


def page_clock(html: str) -> str:
    return re.search(r"data-live-time[^>]*>([^<]*)</dd>", html).group(1)


def list_clock(html: str) -> str:
    return re.search(r"(\d+:\d\d) used of 10 min", html).group(1)


def test_the_page_the_list_and_the_live_stream_count_from_the_trainers_last_word(client, alice):
    job = training_job(alice, seconds=50, ago=0)
    moment = job.clock_at + timedelta(seconds=100.2)  # the trainer busy learning since
    client.force_login(alice)
    with at(moment):
        page = client.get(reverse("training:model-detail", args=[job.model_id])).text
        listed = client.get(reverse("training:model-list")).text
        status = selectors.training_status(job=TrainingJob.objects.get(pk=job.pk))
    assert page_clock(page) == "2:30 used of 10 min · 7:30 left"
    assert list_clock(listed) == "2:30"
    assert status["seconds_used"] == pytest.approx(150.2)
    assert status["server_now"] == pytest.approx(moment.timestamp())
    assert status["clock_running"] is True
    assert f'data-seconds-used="{150.2:.3f}"' in page
    assert f'data-server-now="{moment.timestamp():.3f}"' in page


def test_two_renders_a_moment_apart_share_one_origin(client, alice):
    job = training_job(alice, seconds=61, ago=0)
    client.force_login(alice)
    renders = []
    for later in (2.0, 9.5):
        with at(job.clock_at + timedelta(seconds=later)):
            page = client.get(reverse("training:model-detail", args=[job.model_id])).text
        used = float(re.search(r'data-seconds-used="([\d.]+)"', page).group(1))
        now = float(re.search(r'data-server-now="([\d.]+)"', page).group(1))
        renders.append(now - used)  # the moment the clock read 0
    assert renders[0] == pytest.approx(renders[1], abs=0.01)


def test_a_stop_freezes_the_clock_and_the_trainer_cannot_move_it(alice):
    job = training_job(alice, seconds=300, ago=4)
    stopped = training_stop(job=job)
    assert stopped.status == TrainingJob.Status.STOPPING
    assert stopped.message == "Saving the model from iteration 3"
    assert stopped.training_seconds == pytest.approx(304, abs=1)
    later = timezone.now() + timedelta(minutes=3)  # the iteration being learnt takes minutes
    with at(later):
        clock = selectors.training_clock(job=TrainingJob.objects.get(pk=job.pk))
    assert (clock.seconds, clock.running) == (stopped.training_seconds, False)

    trainer_side = TrainingJob.objects.get(pk=job.pk)
    assert leases.clock_write(trainer_side, 487.0) is False  # its own measure, after the update
    assert TrainingJob.objects.get(pk=job.pk).training_seconds == stopped.training_seconds
    assert trainer_side.training_seconds == stopped.training_seconds


def test_the_clock_stops_at_the_time_limit(alice):
    job = training_job(alice, seconds=590, ago=30)
    clock = selectors.training_clock(job=job)
    assert (clock.seconds, clock.running, clock.left) == (600, False, 0)


def test_the_stop_page_says_what_stopping_does_before_it_stops(client, alice):
    job = training_job(alice, seconds=125, ago=0)
    client.force_login(alice)
    url = reverse("training:model-stop", args=[job.model_id])
    page = client.get(url).text
    assert "Stop training clocked?" in page
    assert "the model keeps the weights of its last finished iteration" in page
    assert "iteration 3" in page and "billed for the time used up to the stop" in page
    assert TrainingJob.objects.get(pk=job.pk).status == TrainingJob.Status.IN_PROGRESS
    response = client.post(url, follow=True)
    assert "Stopping: saving the model from iteration 3." in response.text
    assert TrainingJob.objects.get(pk=job.pk).stop_requested
