"""Training end to end on the real parts: a Celery worker, Redis, the sandbox, SB3."""

import csv
import importlib
import io
import json
from datetime import timedelta

import gymnasium
import msgpack
import pytest
from django.core.files.storage import default_storage
from django.core.management import call_command
from django.db import connection
from django.utils import timezone

import simulator
from analysis.models import TraceSummary
from common.redis_client import redis_client
from jobs import tasks, trainer
from rl import hyperparameters
from rl.experience import JobChannel, decode_episode
from rl.learner import Learner
from rl.stopwatch import PHASES
from sandbox import MiB, Sandbox
from simulator.trace import SimTraceRow
from tests.helpers.training import queued_job, reload, settings, wait_for_job
from tests.helpers.training_logs import assert_training_logs_read_as_recorded
from tests.services import wait_for
from training import artifacts, configuration, leases, rewards
from training.models import Iteration, RLModel, TrainingJob
from training.rewards import EXAMPLES
from training.services import model_create, training_stop


def iterations(job, count: int) -> None:
    """``count`` iterations of ``job`` recorded, as its trainer records them."""
    for number in range(1, count + 1):
        Iteration.objects.create(
            job=job,
            number=number,
            reward=1.0,
            completion=10.0,
            episodes=5,
            steps=50,
            wall_seconds=1.0,
        )


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_short_training_job_runs_end_to_end_and_stop_yields_a_model(
    alice, tracks, celery_worker_process
):
    # fewer evaluation episodes than DeepRacer's 5 (DR_TRAIN_MIN_EVAL_TRIALS): the trainer asks
    # for them, the first worker drives them and the iteration records them
    model = model_create(owner=alice, settings=settings(evaluation_trials=3))
    job = model.jobs.get()
    assert job.status == TrainingJob.Status.QUEUED

    job = wait_for_job(job, lambda j: j.iterations >= 2, "two policy updates")
    assert job.status == TrainingJob.Status.IN_PROGRESS
    assert job.weights_version >= 2
    assert job.episodes >= 10 and job.steps > 0  # experience came through the Redis buffer
    rows = list(Iteration.objects.filter(job=job).order_by("number"))
    assert [row.number for row in rows[:2]] == [1, 2]
    assert all(row.episodes >= 5 and row.steps > 0 for row in rows)
    wait_for(
        lambda: Iteration.objects.filter(job=job, evaluation_completion__isnull=False).exists(),
        "an evaluation after an update",
        timeout=120,
    )
    evaluated = Iteration.objects.filter(job=job, evaluation_completion__isnull=False).first()
    assert evaluated.evaluation_seconds > 0 and len(evaluated.evaluation_points) == 3

    training_stop(job=job)
    job = wait_for_job(job, lambda j: j.status == TrainingJob.Status.COMPLETED, "the stop", 120)
    assert job.model.status == RLModel.Status.READY
    assert default_storage.exists(job.last_checkpoint)
    assert default_storage.exists(job.best_checkpoint)
    prefix = f"models/{model.pk}/"
    metadata = json.loads(default_storage.open(prefix + "model_metadata.json").read())
    assert metadata["training_algorithm"] == "clipped_ppo"
    assert metadata["action_space_type"] == "discrete"
    assert len(metadata["action_space"]) == 10
    metrics = json.loads(default_storage.open(prefix + "metrics/training_metrics.json").read())
    assert metrics["best_model_metric"] == "progress"
    phases = {entry["phase"] for entry in metrics["metrics"]}
    assert phases == {"training", "evaluation"}
    # DeepRacer counts its trace files from 0: iteration 1's is 0-iteration.csv.
    trace = default_storage.open(prefix + "training-simtrace/0-iteration.csv").read().decode()
    table = list(csv.DictReader(io.StringIO(trace)))
    # Each episode's rows: DeepRacer's prepare row (step 1), then one per step.
    assert len(table) == rows[0].steps + rows[0].episodes
    assert table[0]["episode_status"] == "prepare" and table[0]["steps"] == "1.0"
    assert table[0]["track_len"]
    assert job.log_lines.filter(text__startswith="Training started").exists()
    assert job.log_lines.filter(text="Stopped by the racer.").exists()
    assert job.log_lines.filter(text__startswith="Iteration 1: ").exists()
    assert all(row.episodes == 5 for row in rows)  # DeepRacer's: exactly those of an iteration
    assert_training_logs_read_as_recorded(job.model)
    # The iterations finished between the first look and the stop count too; each is whole now
    # (an iteration's row is written before its time split, which ends it).
    rows = list(Iteration.objects.filter(job=job).order_by("number"))
    for row in rows:  # where each iteration's time went, adding up to its wall time
        assert set(row.time_split) == set(PHASES)
        assert sum(row.time_split.values()) == pytest.approx(row.wall_seconds, abs=1e-6)
        assert row.time_split["driving"] > 0 and row.time_split["update"] > 0
    # Each iteration's trace was summarised for the Analysis tab as the trainer recorded it.
    summaries = {s.iteration: s for s in TraceSummary.objects.filter(job=job)}
    assert sorted(summaries) == [row.number for row in rows]
    for row in rows:
        assert len(summaries[row.number].episodes) == row.episodes
        assert summaries[row.number].steps == row.steps


@pytest.mark.django_db(transaction=True)
def test_a_second_delivery_of_the_trainer_task_does_not_train_twice(alice, tracks):
    job = queued_job(alice)
    held = leases.lease_acquire(job_id=job.pk, owner="first-run")
    assert held is not None and held.attempt == 1

    started = []
    assert (
        trainer.run(job.pk, owner="second-run", start_rollouts=lambda *a: started.append(a))
        is False
    )
    job = reload(job)
    assert (job.attempt, job.lease_owner, started) == (1, "first-run", [])

    # The first run's lease lapses (its worker died): the next delivery takes over, and the old
    # run can no longer write.
    TrainingJob.objects.filter(pk=job.pk).update(lease_expires=None, lease_owner="")
    taken = leases.lease_acquire(job_id=job.pk, owner="second-run")
    assert taken.attempt == 2
    with pytest.raises(leases.LeaseLost):
        leases.write(held, message="a stale run writing")


@pytest.mark.django_db(transaction=True)
def test_evaluations_that_come_after_the_next_update_mark_their_own_checkpoint_best(alice, tracks):
    """Evaluations drive beside the next iteration: checkpoint 1's results may come in pieces,
    after iteration 2 was learnt; each is recorded on its own iteration once whole, and the best
    checkpoint is the one that drove them."""
    job = leases.lease_acquire(job_id=queued_job(alice).pk, owner="this-run")
    run = trainer.Trainer(job, start_rollouts=lambda *args: None)
    iterations(job, 2)

    def results(version: int, progress: float, count: int) -> None:
        for _ in range(count):
            run.channel.push_evaluation(
                msgpack.packb(
                    {
                        "version": version,
                        "progress": progress,
                        "lap_time": None,
                        "status": "off_track",
                        "steps": 30,
                        "seconds": 0.5,
                    }
                )
            )

    results(1, 80.0, 3)
    results(2, 40.0, 5)
    run._take_evaluations()
    assert reload(job).best_checkpoint.endswith(artifacts.checkpoint(2))
    first = Iteration.objects.get(job=job, number=1)
    assert first.evaluation_completion is None  # 3 of its 5 results so far
    results(1, 80.0, 2)
    run._take_evaluations()
    first.refresh_from_db()
    assert (first.evaluation_completion, first.evaluation_seconds) == (80.0, 2.5)
    assert first.evaluation_points == [80.0] * 5
    assert reload(job).best_checkpoint.endswith(artifacts.checkpoint(1))


@pytest.mark.django_db(transaction=True)
def test_of_checkpoints_that_evaluate_alike_the_newer_is_best_as_in_deepracer(alice, tracks):
    """DeepRacer's best model is the highest mean evaluation progress, a tie going to the newer
    checkpoint whatever its laps (simapp's s3_metrics.py); so it stays when the trainer resumes."""
    job = leases.lease_acquire(job_id=queued_job(alice).pk, owner="this-run")
    run = trainer.Trainer(job, start_rollouts=lambda *args: None)
    iterations(job, 3)

    def results(version: int, progress: float, lap_time: float | None) -> None:
        for _ in range(5):
            run.channel.push_evaluation(
                msgpack.packb(
                    {
                        "version": version,
                        "progress": progress,
                        "lap_time": lap_time,
                        "status": "lap_complete" if lap_time else "off_track",
                        "steps": 30,
                        "seconds": 0.5,
                    }
                )
            )

    results(2, 100.0, 7.5)
    results(1, 100.0, 7.0)  # faster, but older and recorded later
    run._take_evaluations()
    assert reload(job).best_checkpoint.endswith(artifacts.checkpoint(2))
    results(3, 100.0, 9.0)
    run._take_evaluations()
    assert reload(job).best_checkpoint.endswith(artifacts.checkpoint(3))

    # A resumed trainer picks among all the job's evaluated iterations, not only its own.
    resumed = trainer.Trainer(reload(job), start_rollouts=lambda *args: None)
    resumed._recall_progress()
    Iteration.objects.create(
        job=job, number=4, reward=1.0, completion=10.0, episodes=5, steps=50, wall_seconds=1.0
    )
    results(4, 90.0, None)
    resumed._take_evaluations()
    assert reload(job).best_checkpoint.endswith(artifacts.checkpoint(3))


@pytest.mark.django_db(transaction=True)
def test_the_models_best_checkpoint_metric_picks_the_best_as_dr_train_best_model_metric(
    alice, tracks
):
    """By lap time the faster checkpoint is best, by reward the better rewarded, where by
    progress (all 100%) the newer would be."""
    job = leases.lease_acquire(job_id=queued_job(alice).pk, owner="this-run")
    iterations(job, 2)
    picked = {}
    for metric in ("laptime", "reward", "progress"):
        RLModel.objects.filter(pk=job.model_id).update(best_checkpoint_by=metric)
        run = trainer.Trainer(reload(job), start_rollouts=lambda *args: None)
        for version, lap_time, reward in ((1, 7.0, 50.0), (2, 7.5, 80.0)):
            for _ in range(5):
                run.channel.push_evaluation(
                    msgpack.packb(
                        {
                            "version": version,
                            "progress": 100.0,
                            "lap_time": lap_time,
                            "reward": reward,
                            "status": "lap_complete",
                            "steps": 105,
                            "seconds": 0.5,
                        }
                    )
                )
        run._take_evaluations()
        picked[metric] = artifacts.checkpoint_iteration(reload(job).best_checkpoint)
        metrics = json.loads(artifacts.read(artifacts.path(job.model, artifacts.TRAINING_METRICS)))
        assert metrics["best_model_metric"] == metric  # as simapp writes it
    assert picked == {"laptime": 1, "reward": 2, "progress": 2}
    row = Iteration.objects.get(job=job, number=1)
    assert (row.evaluation_reward, row.evaluation_lap_ms) == (50.0, 7000.0)


@pytest.mark.django_db(transaction=True)
def test_a_queued_job_that_is_stopped_is_canceled(alice, tracks):
    job = training_stop(job=queued_job(alice))
    model = job.model
    assert job.status == TrainingJob.Status.CANCELED
    assert RLModel.objects.get(pk=model.pk).status == RLModel.Status.ERROR


@pytest.mark.django_db
class TestSettings:
    def errors(self, owner, **changes) -> dict:
        with pytest.raises(configuration.Invalid) as invalid:
            configuration.check(settings(**changes), owner=owner, validate_reward=False)
        return invalid.value.errors

    def test_valid_settings_are_completed_with_defaults(self, alice, tracks):
        clean = configuration.check(
            settings(hyperparameters={}), owner=alice, validate_reward=False
        )
        assert clean.hyperparameters == hyperparameters.defaults("clipped_ppo")
        assert clean.action_space_type == "discrete"
        assert clean.action_space[0] == {"steering_angle": -30.0, "speed": 0.5, "index": 0}
        assert clean.direction == "counterclockwise" and clean.workers == 1

    @pytest.mark.parametrize(
        ("changes", "field", "message"),
        [
            ({"name": "my model!"}, "name", "1-64 letters, digits and hyphens"),
            ({"description": "x" * 256}, "description", "at most 255"),
            ({"track": "monza"}, "track", "Choose one of the listed tracks"),
            ({"track": "championship-circuit", "direction": "clockwise"}, "direction",
             "cannot be driven clockwise"),
            ({"race_type": "OBJECT_AVOIDANCE", "boxes": {"count": 9}}, "race_type",
             "number of boxes must be a whole number from 1 to 6"),
            ({"race_type": "HEAD_TO_BOT", "bots": {"speed": 9}}, "race_type", "0.2-6.0 m/s"),
            ({"sensors": ["LIDAR"]}, "sensors", "exactly one camera"),
            ({"network": "RESNET"}, "network", "3-layer or the 5-layer"),
            ({"action_space": [{"steering_angle": 40, "speed": 1}] * 2},
             "action_space.0.steering_angle", "-30 to 30 degrees"),
            ({"algorithm": "sac"}, "algorithm", "SAC needs a continuous action space"),
            ({"hyperparameters": {"batch_size": 100}}, "hyperparameters.batch_size",
             "one of 32, 64, 128, 256, 512"),
            ({"hyperparameters": {"lr": 0.1}}, "hyperparameters.lr", "between 1e-08 and 0.001"),
            ({"hyperparameters": {"num_epochs": 2}}, "hyperparameters.num_epochs", "3 and 10"),
            ({"hyperparameters": {"loss_type": "l1"}}, "hyperparameters.loss_type",
             "one of Huber, mean squared error"),
            ({"hyperparameters": {"clip_range": 0.2}}, "hyperparameters.clip_range",
             "“clip_range” is not one of DeepRacer's hyperparameters; they are batch_size"),
            ({"hyperparameters": {"exploration_type": "random"}},
             "hyperparameters.exploration_type", "one of categorical, e-greedy"),
            ({"max_minutes": 5}, "max_minutes", "10 to 1440 minutes"),
            ({"workers": 9}, "workers", "1 to 4"),
            ({"extra_tracks": ["speedway"]}, "extra_tracks", "needs a simulation of its own"),
            ({"reward_function": "  "}, "reward_function", "Write a reward function"),
        ],
    )  # fmt: skip
    def test_each_bad_setting_gets_its_own_message(self, alice, tracks, changes, field, message):
        errors = self.errors(alice, **changes)
        assert message in errors[field], errors

    @pytest.mark.parametrize(
        ("given", "stored"),
        [("huber", "huber"), ("Huber", "huber"), ("mean squared error", "mean squared error"),
         ("Mean Squared Error", "mean squared error"), ("mse", "mean squared error")],
    )  # fmt: skip
    def test_the_loss_type_takes_deepracers_spellings_and_the_old_mse(
        self, alice, tracks, given, stored
    ):
        clean = configuration.check(
            settings(hyperparameters={"loss_type": given}), owner=alice, validate_reward=False
        )
        assert clean.hyperparameters["loss_type"] == stored

    def test_deepracers_keys_pitlane_does_not_use_are_kept_with_the_model(self, alice, tracks):
        kept = {
            "stack_size": 2,
            "exploration_type": "E-Greedy",
            "e_greedy_value": 0.1,
            "epsilon_steps": 5000,
            "term_cond_max_episodes": 1000,
            "term_cond_avg_score": 350.0,
            "sac_alpha": 0.3,
        }
        model = model_create(
            owner=alice, settings=settings(hyperparameters=kept), validate_reward=False
        )
        model.refresh_from_db()
        assert model.hyperparameters == {
            **hyperparameters.defaults("clipped_ppo"),
            **kept,
            "exploration_type": "e-greedy",
        }
        # A new model has DeepRacer's defaults (discount 0.999 as simapp falls back to) for all.
        defaults = configuration.check(
            settings(name="new", hyperparameters={}), owner=alice, validate_reward=False
        ).hyperparameters
        assert defaults["discount_factor"] == 0.999 and defaults["stack_size"] == 1
        assert defaults["term_cond_avg_score"] == 100000 and "sac_alpha" not in defaults

    def test_the_data_migration_respells_a_stored_mse_as_deepracer_does(self, alice, tracks):
        from django.apps import apps

        migration = importlib.import_module(
            "training.migrations.0010_loss_type_spelled_as_deepracer"
        )
        old = model_create(owner=alice, settings=settings(), validate_reward=False)
        RLModel.objects.filter(pk=old.pk).update(
            hyperparameters={**old.hyperparameters, "loss_type": "mse"}
        )
        migration.forwards(apps, None)
        old.refresh_from_db()
        assert old.hyperparameters["loss_type"] == "mean squared error"
        migration.backwards(apps, None)
        old.refresh_from_db()
        assert old.hyperparameters["loss_type"] == "mse"

    def test_sac_with_a_continuous_action_space_is_fine(self, alice, tracks):
        continuous = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 1, "high": 2}}
        clean = configuration.check(
            settings(algorithm="sac", action_space=continuous, hyperparameters={}),
            owner=alice,
            validate_reward=False,
        )
        assert clean.hyperparameters["sac_alpha"] == 0.2
        assert clean.action_space_type == "continuous"

    def test_a_name_already_used_by_the_racer_is_refused_but_not_another_racers(
        self, alice, bob, tracks
    ):
        model_create(owner=bob, settings=settings(), validate_reward=False)
        configuration.check(settings(), owner=alice, validate_reward=False)
        model_create(owner=alice, settings=settings(), validate_reward=False)
        assert "already have a model named “tiny-oval”" in self.errors(alice)["name"]

    def test_a_clone_that_changes_sensors_is_refused(self, alice, tracks):
        source = model_create(owner=alice, settings=settings(), validate_reward=False)
        RLModel.objects.filter(pk=source.pk).update(status=RLModel.Status.READY)
        source.refresh_from_db()
        errors = self.errors(alice, name="clone", cloned_from=source, sensors=["STEREO_CAMERAS"])
        assert "A clone keeps its source's sensors (FRONT_FACING_CAMERA)" in errors["sensors"]

    def test_a_reward_function_that_fails_validation_is_refused_with_its_line(self, alice, tracks):
        with pytest.raises(configuration.Invalid) as invalid:
            configuration.check(
                settings(reward_function="import os\ndef reward_function(params):\n    return 1\n"),
                owner=alice,
            )
        assert invalid.value.errors["reward_function"].startswith("import (line 1): Only math")
        assert not RLModel.objects.exists()


@pytest.mark.django_db
def test_the_createmodel_command_creates_a_queued_model(alice, tracks, tmp_path, capsys):
    (tmp_path / "model.yaml").write_text("name: from-yaml\ntrack: rookie-loop\nmax_minutes: 30\n")
    (tmp_path / "reward.py").write_text(EXAMPLES[1].source)
    call_command(
        "createmodel", config=tmp_path / "model.yaml", reward=tmp_path / "reward.py", owner="alice"
    )
    model = RLModel.objects.get(name="from-yaml")
    assert (model.max_minutes, model.jobs.get().status) == (30, "QUEUED")
    assert "its training is queued" in capsys.readouterr().out


@pytest.mark.django_db(transaction=True)
def test_creating_a_model_validates_its_reward_function_before_any_transaction(
    alice, tracks, monkeypatch
):
    validate = rewards.reward_validate
    in_transaction = []

    def watched(**kwargs):  # the real validation, noting whether a transaction was open
        in_transaction.append(connection.in_atomic_block)
        return validate(**kwargs)

    monkeypatch.setattr(rewards, "reward_validate", watched)
    model = model_create(owner=alice, settings=settings(name="validated-first"))
    assert in_transaction == [False]
    assert model.jobs.get().status == TrainingJob.Status.QUEUED

    with pytest.raises(configuration.Invalid) as invalid:
        model_create(
            owner=alice,
            settings=settings(
                name="refused", reward_function="def reward_function(params):\n    return 'fast'\n"
            ),
        )
    assert in_transaction == [False, False]
    assert "reward_function" in invalid.value.errors
    assert not RLModel.objects.filter(name="refused").exists()


@pytest.mark.slow
@pytest.mark.django_db(transaction=True)
def test_a_trainer_that_died_is_resumed_from_its_last_checkpoint(
    alice, tracks, celery_worker_process
):
    # The state a dead trainer leaves: in progress, a lapsed lease, a checkpoint of iteration 1.
    clean = configuration.check(settings(name="resumed"), owner=alice, validate_reward=False)
    model = RLModel.objects.create(owner=alice, status=RLModel.Status.TRAINING, **clean.row())
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
    learner = Learner.for_model(model, env)
    checkpoint = artifacts.save(model, "checkpoints/iteration-1.safetensors", learner.checkpoint())
    now = timezone.now()
    job = TrainingJob.objects.create(
        model=model,
        status=TrainingJob.Status.IN_PROGRESS,
        attempt=1,
        lease_owner="dead:1",
        lease_expires=now - timedelta(seconds=1),
        started_at=now - timedelta(minutes=1),
        training_seconds=30,
        weights_version=1,
        iterations=1,
        episodes=5,
        steps=100,
        last_checkpoint=checkpoint,
        best_checkpoint=checkpoint,
    )
    Iteration.objects.create(
        job=job, number=1, reward=1, completion=5, episodes=5, steps=100, wall_seconds=1
    )

    tasks.train.delay(job.pk)  # the redelivered task
    job = wait_for_job(job, lambda j: j.iterations >= 2, "an update after resuming")
    assert job.attempt == 2
    assert job.log_lines.filter(
        text="Resumed from the checkpoint of iteration 1 (attempt 2)."
    ).exists()
    assert job.training_seconds > 30  # the time used before counts
    training_stop(job=job)
    job = wait_for_job(job, lambda j: j.status == TrainingJob.Status.COMPLETED, "the stop", 120)
    assert job.model.status == RLModel.Status.READY


@pytest.mark.django_db(transaction=True)
def test_a_worker_that_outlived_a_redis_restart_neither_miscounts_nor_drives_on():
    channel = JobChannel(redis_client(), job_id=987_655)
    channel.start(attempt=1)
    old = channel.join(1)
    assert old is not None and channel.join(2) is None
    # Redis restarts: the job's keys are gone. The old run's worker, whose client retried its
    # push on the new server, files the episode it was driving before the trainer notices.
    channel.client.delete(channel.experience, channel.counts, channel.control, channel.policy)
    assert channel.should_stop(old)
    channel.push_episode(b"old", version=3)
    channel.start(attempt=1)  # the trainer's new run, as Redis came back
    new = channel.join(1)
    assert new != old and channel.should_stop(old) and not channel.should_stop(new)
    pushed = [channel.push_episode(f"new {i}".encode(), version=3) for i in range(5)]
    # The new run's worker stops at its share, which the buffer holds all of: nothing is counted
    # that the trainer will not receive.
    assert pushed == [1, 2, 3, 4, 5]
    assert channel.pop_episodes(limit=10) == [f"new {i}".encode() for i in range(5)]


@pytest.mark.slow
def test_sac_learns_from_random_episodes_driven_in_the_sandbox():
    continuous = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2}}
    env = gymnasium.make(simulator.ENV_ID, track="pitlane-oval", action_space=continuous)
    sac = {**hyperparameters.defaults("sac"), "batch_size": 32}
    learner = Learner(
        algorithm="sac",
        hyperparameters=sac,
        architecture=model_network(),
        observation_space=env.observation_space,
        action_space=env.action_space,
    )
    before = learner.policy_weights()
    policy = {"algorithm": "sac", "architecture": model_network()}
    with Sandbox(
        env={"track": "pitlane-oval", "action_space": continuous},
        policy=policy,
        memory_allowance=1024 * MiB,
    ) as sandbox:
        sandbox.load(EXAMPLES[0].source)
        sandbox.set_weights(0, before)
        payload = sandbox.episode("random")["payload"]
        episode = decode_episode(payload, env.observation_space, env.action_space, ppo=False)
        prepare = SimTraceRow(*episode.trace[0])  # DeepRacer's first row: step 1, no reward
        assert (prepare.steps, prepare.episode_status, prepare.reward) == (1.0, "prepare", 0.0)
        assert len(episode.trace) == episode.steps + 1
        update = learner.learn([episode])
        assert (update.episodes, update.steps) == (1, episode.steps)
        assert learner.policy_weights() != before  # the actor learnt
        sandbox.set_weights(1, learner.policy_weights())
        summary = sandbox.episode("evaluate")["summary"]
    assert summary["version"] == 1 and summary["steps"] > 0


def model_network() -> str:
    return "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"
