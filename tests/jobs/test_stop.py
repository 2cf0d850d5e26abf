"""Stopping a training on the real parts (a Celery worker, Redis, the sandbox, SB3): the trainer
abandons an update it is in the middle of, the job ends at once with the model of its last
finished iteration, and it is billed the time up to the stop. What the reward function printed
reaches the job's log, a bounded share of it."""

import re

import gymnasium
import pytest

import simulator
from common.redis_client import redis_client
from jobs import rollouts, tasks
from rl import hyperparameters
from rl.experience import JobChannel
from rl.learner import Interrupted, Learner
from tests.helpers.learning import synthetic_episode
from tests.helpers.training import (
    TINY_PPO,
    sandbox_children,
    settings,
    wait_for_job,
)
from tests.services import wait_for
from training import configuration
from training.models import Iteration, JobLogLine, RLModel, TrainingJob
from training.services import training_stop

PRINTING = """\
def reward_function(params):
    print("progress", params["progress"], "steps", params["steps"])
    return 1.0
"""


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_stop_in_the_middle_of_an_update_abandons_it_and_bills_the_time_up_to_the_stop(
    alice, tracks, celery_worker_process
):
    clean = configuration.check(
        settings(name="long-update", reward_function=PRINTING), owner=alice, validate_reward=False
    )
    # An update that would take hours: far more epochs than a racer may choose.
    clean = clean.replace(
        hyperparameters={
            **hyperparameters.defaults("clipped_ppo"),
            **TINY_PPO,
            "num_epochs": 100_000,
        }
    )
    model = RLModel.objects.create(owner=alice, **clean.row())
    job = TrainingJob.objects.create(model=model)
    tasks.train.delay(job.pk)
    job = wait_for_job(
        job,
        lambda j: j.message.endswith("(iteration 1, from 5 episodes)"),
        "the first update to begin",
    )
    # The page tells how far the update has gone, and its time left at the pace so far.
    job = wait_for_job(job, lambda j: "left" in j.message, "the update's first estimate")
    assert re.fullmatch(
        r"Updating the policy: epoch \d+ of 100000, about \d+:\d\d left "
        r"\(iteration 1, from 5 episodes\)",
        job.message,
    )

    stopping = training_stop(job=job)
    assert stopping.status == TrainingJob.Status.STOPPING
    assert stopping.message == "Saving the model as it started: no iteration finished"

    # The update would go on for hours: the job ends only because the trainer abandoned it.
    job = wait_for_job(job, lambda j: j.status == TrainingJob.Status.COMPLETED, "the stop", 90)
    assert job.iterations == 0 and not Iteration.objects.filter(job=job).exists()
    assert job.model.status == RLModel.Status.READY
    assert job.training_seconds == stopping.training_seconds  # billed up to the stop, no more
    assert job.clock_at == stopping.clock_at
    assert job.log_lines.filter(text="Stopped by the racer.").exists()
    assert job.log_lines.filter(
        text="Iteration 1 was being learnt and was abandoned; the model is saved from iteration 0."
    ).exists()

    # What the reward function printed: the first lines of the iteration, then how many more.
    printed = job.log_lines.filter(source=JobLogLine.Source.REWARD)
    kept = printed.filter(text__startswith="progress ")
    assert 0 < kept.count() <= rollouts.PRINTED_LINES
    (note,) = printed.exclude(text__startswith="progress ")
    assert note.text.startswith("… ") and note.text.endswith(
        " more lines printed in iteration 1 not kept"
    )
    assert job.log_lines.filter(
        source=JobLogLine.Source.WORKER,
        text="Simulation worker 1 is driving Pitlane Oval, its cars' policy served by the "
        "machine's policy server on the CPU.",
    ).exists()
    assert job.log_lines.filter(text__contains="1 simulation worker,").exists()


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_job_deleted_in_the_middle_of_an_update_frees_its_rollout_worker(
    alice, tracks, celery_worker_process
):
    # A job whose row vanishes (an admin's delete, a test database flushed) says nothing to Redis:
    # its rollout worker, waiting for the next policy, must still end and give back its place.
    before = set(sandbox_children())
    clean = configuration.check(settings(name="vanishing"), owner=alice, validate_reward=False)
    clean = clean.replace(
        hyperparameters={
            **hyperparameters.defaults("clipped_ppo"),
            **TINY_PPO,
            "num_epochs": 100_000,
        }
    )
    model = RLModel.objects.create(owner=alice, **clean.row())
    job = TrainingJob.objects.create(model=model)
    tasks.train.delay(job.pk)
    wait_for_job(
        job,
        lambda j: j.message.endswith("(iteration 1, from 5 episodes)"),
        "the first update to begin",
    )
    ours = set(sandbox_children()) - before
    assert ours  # this job's rollout, waiting while the trainer learns

    TrainingJob.objects.filter(pk=job.pk).delete()
    wait_for(lambda: not ours & set(sandbox_children()), "the rollout to end", timeout=60)
    assert redis_client().hget(JobChannel(redis_client(), job.pk).control, "stop") == b"1"


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", ["clipped_ppo", "sac"])
def test_an_update_is_abandoned_as_soon_as_it_is_told_to(algorithm):
    continuous = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2}}
    settings = {"action_space": continuous} if algorithm == "sac" else {}
    env = gymnasium.make(simulator.ENV_ID, track="pitlane-oval", **settings)
    values = {**hyperparameters.defaults(algorithm), "batch_size": 32}
    learner = Learner(
        algorithm=algorithm,
        hyperparameters=values,
        architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        observation_space=env.observation_space,
        action_space=env.action_space,
    )
    asked = []

    def interrupted() -> bool:  # the trainer's look at the stop request
        asked.append(True)
        return len(asked) > 1

    with pytest.raises(Interrupted):
        learner.learn([synthetic_episode(env, steps=70)], interrupted=interrupted)
    assert len(asked) == 2  # it looked between steps of the update, and stopped at the first yes
    update = learner.learn([synthetic_episode(env, steps=4)])  # a later update is not affected
    assert update.episodes == 1
