"""The commands that queue a training say so in words when Redis does not answer, and change
nothing: no kombu traceback, no model left queued without its task."""

from __future__ import annotations

import pytest
from django.core.management import CommandError, call_command

from tests.helpers.archives import deepracer_export, tar_gz
from tests.services import free_port
from training.models import RLModel
from training.rewards import EXAMPLES

pytestmark = pytest.mark.django_db


@pytest.fixture
def redis_down(settings) -> str:
    """Celery's broker at a closed port, with a password, as ``make run`` gives one; the URL."""
    settings.CELERY_BROKER_URL = f"redis://:kept-secret@127.0.0.1:{free_port()}/0"
    return settings.CELERY_BROKER_URL


def test_it_imports_nothing_and_says_to_start_redis_when_redis_does_not_answer(
    alice, tracks, tmp_path, redis_down
):
    archive = tmp_path / "model.tar.gz"
    archive.write_bytes(tar_gz(deepracer_export()))  # no weights: its training would be queued
    with pytest.raises(CommandError) as refused:
        call_command("importmodel", str(archive), "--owner", "alice")
    where = redis_down.replace("kept-secret", "**")
    assert str(refused.value) == (
        f"Redis at {where} does not answer: start it (make run does) and try again. "
        "Nothing was imported."
    )
    assert not RLModel.objects.exists()


def test_it_creates_no_model_when_redis_does_not_answer(alice, tracks, tmp_path, redis_down):
    (tmp_path / "model.yaml").write_text("name: from-yaml\ntrack: rookie-loop\n")
    (tmp_path / "reward.py").write_text(EXAMPLES[1].source)
    with pytest.raises(CommandError, match=r"does not answer: .* No model was created\.$"):
        call_command(
            "createmodel",
            config=tmp_path / "model.yaml",
            reward=tmp_path / "reward.py",
            owner="alice",
        )
    assert not RLModel.objects.exists()
