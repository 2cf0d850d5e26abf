"""The page tells where the time goes while it goes: how far the policy update has gone, with the
time it has left, and the episodes counted as the cars end them, not only once learnt."""

import pytest

from common.redis_client import redis_client
from jobs.trainer import UpdateEstimate, update_message
from rl.experience import JobChannel
from tests.helpers.training import trainer_initializing, training_job
from training import selectors, streams
from training.models import TrainingJob

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("tracks")]
ABOUT = "iteration 4, from 20 episodes"


def test_a_ppo_update_says_its_epoch_and_the_time_left():
    assert update_message(90, 300, 10, 84.0, ABOUT) == (
        "Updating the policy: epoch 4 of 10, about 1:24 left (iteration 4, from 20 episodes)"
    )
    assert update_message(299, 300, 10, 1.0, ABOUT).startswith(
        "Updating the policy: epoch 10 of 10, about 0:01 left"
    )


def test_an_update_just_begun_says_its_first_epoch_without_guessing_the_time():
    assert update_message(0, 300, 10, None, ABOUT) == (
        "Updating the policy: epoch 1 of 10 (iteration 4, from 20 episodes)"
    )
    assert UpdateEstimate().report(0, 300, 5.0) is None


def test_a_sac_update_counts_its_gradient_steps():
    assert update_message(1_024, 4_000, 0, 93.0, "iteration 9, from 1 episode") == (
        "Updating the policy: 1,024 of 4,000 gradient steps, about 1:33 left "
        "(iteration 9, from 1 episode)"
    )


def test_it_estimates_the_time_left_from_the_steps_done_not_from_the_updates_start():
    estimate = UpdateEstimate()
    # 20 s copying the rollout to the device before the first of 300 minibatches is done
    assert estimate.report(1, 300, 20.0) is None
    assert estimate.report(20, 300, 21.9) is None  # too few, too soon, to set the pace
    assert estimate.report(31, 300, 23.0) == pytest.approx(0.1 * 269)  # 0.1 s a minibatch


def test_a_long_update_says_its_time_left_within_seconds():
    estimate = UpdateEstimate()
    estimate.report(1, 1_500_000, 0.0)
    assert estimate.report(11, 1_500_000, 1.0) is None
    assert estimate.report(21, 1_500_000, 2.0) == pytest.approx(0.1 * (1_500_000 - 21))


def test_it_never_raises_the_time_left_while_an_epoch_runs():
    estimate, now, said = UpdateEstimate(), 0.0, []
    for done in range(1, 300):
        now += 0.1 if done < 60 or done > 90 else 0.5  # a slower stretch in the third epoch
        left = estimate.report(done, 300, now)
        if left is not None:
            said.append(left)
    assert len(said) > 250
    assert said == sorted(said, reverse=True)
    assert said[-1] < 1.0
    assert estimate.report(300, 300, now + 0.1) is None  # done


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


@pytest.mark.django_db(transaction=True)
def test_the_trainer_tells_the_page_each_episode_as_its_car_ends_it(alice, monkeypatch):
    run = trainer_initializing(alice)
    monkeypatch.setattr(run, "_decode", lambda payload: None)  # no learner to read it with
    told = []
    monkeypatch.setattr(streams, "announce", lambda group, message: told.append(message))
    run.channel.beat(0)
    run._turn()  # the car drives
    told.clear()

    run.channel.push_episode(b"an episode", run.version, 0)
    run._turn()  # seconds before the trainer's next word of its clock
    assert [message["episodes"] for message in told if message["type"] == "status"] == [1]
