"""The page tells where the time goes while it goes: how far the policy update has gone, with the
time it has left, and the episodes counted as the cars end them, not only once learnt."""

import pytest

from common.redis_client import redis_client
from jobs.trainer import update_message
from rl.experience import JobChannel
from tests.helpers.training import training_job
from training import selectors
from training.models import TrainingJob

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]
ABOUT = "iteration 4, from 20 episodes"


def test_a_ppo_update_says_its_epoch_and_the_time_left_at_the_pace_so_far():
    # 10 epochs of 30 minibatches: 90 done in 36 s is 0.4 s each, 210 to go.
    assert update_message(90, 300, 10, 36.0, ABOUT) == (
        "Updating the policy: epoch 4 of 10, about 1:24 left (iteration 4, from 20 episodes)"
    )
    assert update_message(299, 300, 10, 299.0, ABOUT).startswith(
        "Updating the policy: epoch 10 of 10, about 0:01 left"
    )


def test_an_update_just_begun_says_its_first_epoch_without_guessing_the_time():
    assert update_message(0, 300, 10, 0.0, ABOUT) == (
        "Updating the policy: epoch 1 of 10 (iteration 4, from 20 episodes)"
    )


def test_a_sac_update_counts_its_gradient_steps():
    assert update_message(1_024, 4_000, 0, 32.0, "iteration 9, from 1 episode") == (
        "Updating the policy: 1,024 of 4,000 gradient steps, about 1:33 left "
        "(iteration 9, from 1 episode)"
    )


@pytest.fixture
def channel():
    """A job's keys in Redis, as its trainer starts them."""
    made = []

    def make(job: TrainingJob) -> JobChannel:
        made.append(JobChannel(redis_client(), job.pk))
        made[-1].start(job.attempt)
        return made[-1]

    yield make
    for job_channel in made:
        job_channel.client.delete(job_channel.counts, job_channel.experience, job_channel.control)


def test_the_page_counts_each_episode_as_it_arrives_not_only_once_learnt(alice, channel):
    job = training_job(alice, seconds=60, ago=1, episodes=40, weights_version=2, steps=4000)
    job = TrainingJob.objects.select_related("model").get(pk=job.pk)
    assert job.model.hyperparameters["num_episodes_between_training"] == 5
    buffer = channel(job)
    assert selectors.training_status(job=job)["episodes"] == 40

    for _ in range(3):
        buffer.push_episode(b"episode", 2)
    buffer.push_episode(b"driven with the weights before", 1)  # PPO drops it
    assert selectors.training_status(job=job)["episodes"] == 43

    # While the trainer learns from its 5 they stay counted; a worker's 6th never is.
    for _ in range(3):
        buffer.push_episode(b"episode", 2)
    assert selectors.training_status(job=job)["episodes"] == 45

    # Learnt: the same 45, now in the job's own count.
    TrainingJob.objects.filter(pk=job.pk).update(episodes=45, weights_version=3)
    job.refresh_from_db()
    assert selectors.training_status(job=job)["episodes"] == 45


def test_a_stopped_job_counts_only_the_episodes_it_learnt_from(alice, channel):
    job = training_job(alice, seconds=60, ago=1, episodes=40, weights_version=2)
    buffer = channel(job)
    for _ in range(5):
        buffer.push_episode(b"episode", 2)
    TrainingJob.objects.filter(pk=job.pk).update(status=TrainingJob.Status.STOPPING)
    job.refresh_from_db()
    assert selectors.training_status(job=job)["episodes"] == 40
