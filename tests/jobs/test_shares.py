"""Each training's share of the machine (jobs.shares): equal, unless staff give a racer more."""

import pytest
import torch

from jobs.shares import rollout_niceness, share_cores
from tests.helpers.training import training_job
from training.models import Quota

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]


@pytest.fixture
def torch_threads():
    """The test process's PyTorch threads, put back after the test."""
    threads = torch.get_num_threads()
    yield
    torch.set_num_threads(threads)


def test_a_heavier_racers_training_takes_more_cores_and_drives_at_full_priority(
    alice, bob, settings, monkeypatch, torch_threads
):
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: set(range(16)))
    settings.PITLANE_TRAINER_THREADS = 16
    alices, bobs = training_job(alice, seconds=60, ago=1), training_job(bob, seconds=60, ago=1)

    share_cores(alices.pk)  # equal shares: half the cores each, cars at the same priority
    assert torch.get_num_threads() == 8
    assert rollout_niceness(alices.pk) == rollout_niceness(bobs.pk) == 0

    Quota.objects.filter(pk=Quota.of(alice).pk).update(machine_share=3)  # staff, in the admin
    share_cores(alices.pk)
    assert torch.get_num_threads() == 12  # 3 of 4 shares
    share_cores(bobs.pk)
    assert torch.get_num_threads() == 4
    assert rollout_niceness(alices.pk) == 0
    assert rollout_niceness(bobs.pk) == 5  # Linux's weight at 5 is 335 against 1024: a third
