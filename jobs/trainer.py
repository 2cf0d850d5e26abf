"""The trainer: the loop of one training job, run by the ``training.train`` task.

It holds the job's lease, builds the learner, publishes weights, starts the rollout workers, and
then learns from the episodes they push to Redis, one policy update at a time, recording each
iteration, checkpointing and watching its workers, until the racer stops it, the time limit
comes, or something fails. It is the only writer of the job's rows while it holds the lease.

Long because the loop and each of its ways out (a stop, the time limit, a lost lease, a worker
that died, Redis that went away, an evaluation that came late) are one state machine, read
together.
"""

from __future__ import annotations

import contextlib
import functools
import json
import logging
import time
from dataclasses import dataclass, field

import gymnasium
import redis
from django.conf import settings
from django.core.files.storage import default_storage
from django.db import transaction
from django.db.models import Sum
from django.utils import timezone

import simulator
from common.every import Every
from common.formatting import clock
from common.redis_client import redis_client
from jobs import checkpoints
from jobs.shares import share_cores
from notifications import services as notifications
from rl import hyperparameters as hp
from rl.experience import Episode, JobChannel, decode_episode
from rl.learner import Interrupted, Learner, Progress
from rl.stopwatch import CHECKS, DRIVING, PHASES, SAVING, TRANSFER, UPDATE, Stopwatch
from sandbox.protocol import unpack
from simulator.config import CONTROL_HZ
from simulator.trace import SimTraceRow, to_csv
from training import artifacts, leases, lifecycle, services, signals, streams
from training.leases import LeaseLost
from training.models import Iteration, JobLogLine, RLModel, Track, TrainingJob

logger = logging.getLogger(__name__)

CHECK_EVERY = 3.0  # [s] between lease renewals, clock writes and worker checks
STOP_CHECK = 1.0  # [s] between looks for the racer's stop request, even in the middle of an update
UPDATE_SAID_EVERY = 1.5  # [s] at least between two words of how far the update has gone
# [s] at least between two words of the episodes that arrived: each costs a query, a Redis
# connection and a group send in the learner's loop, and short early episodes come in bursts
EPISODES_TOLD_EVERY = 0.5
REPLACEMENTS = 2  # per worker slot, before the job carries on without it
REDIS_PATIENCE = 60.0  # [s] the trainer waits for a Redis that went away
MAX_PRINTED_LINES = 20_000  # reward function and worker lines a job's log keeps, in all
WAITING_FOR_WORKER = "Waiting for a free simulation worker; the clock starts when the car drives"
WORKER_PATIENCE = 30 * 60  # [s] a job waits for its first simulation worker, unbilled
NO_WORKER = (
    f"No simulation worker took this job's rollouts in {WORKER_PATIENCE // 60} minutes: they "
    "were all busy, or none serves the simulation queue. You were not billed for the wait; "
    "start the training again later."
)


class JobFailed(Exception):
    """The job cannot go on; the message is for the racer."""


@dataclass
class Slot:
    """A rollout worker the job wants: its track, when it was (re)started, how often."""

    index: int
    track: str
    started: float = field(default_factory=time.monotonic)
    started_wall: float = field(default_factory=time.time)
    replacements: int = 0
    gone: bool = False


def run(job_id: int, owner: str, start_rollouts, queued_rollouts=None) -> bool:
    """Train job ``job_id`` while this run holds its lease. ``start_rollouts(job, slot)`` enqueues a
    rollout worker, and ``queued_rollouts(job)`` says which slots' rollouts still wait in the
    broker's queue (None: it cannot tell); the task module passes both, so this module stays
    free of Celery. False when another run holds a live lease: the caller tries again later, and
    takes the job over if that run has died (its lease expired)."""
    job = leases.lease_acquire(job_id=job_id, owner=owner)
    if job is None:
        held = TrainingJob.objects.filter(pk=job_id, status__in=TrainingJob.ACTIVE).exists()
        logger.info("Training job %s is %s", job_id, "held by another run" if held else "over")
        return not held
    trainer = Trainer(job, start_rollouts, queued_rollouts)
    try:
        trainer.train()
    except LeaseLost:
        if TrainingJob.objects.filter(pk=job_id, status__in=TrainingJob.ACTIVE).exists():
            logger.warning("Training job %s was taken over by another run; this one stops", job_id)
        else:  # deleted under the run: no other run will tell its rollout workers
            logger.warning("Training job %s vanished; its rollout workers are told to stop", job_id)
            with contextlib.suppress(redis.RedisError):
                trainer.channel.request_stop()
    except JobFailed as failure:
        trainer.finish(TrainingJob.Status.FAILED, reason=str(failure))
    except redis.RedisError as error:
        trainer.finish(
            TrainingJob.Status.FAILED, reason=f"Redis was lost during training ({error})."
        )
    except Exception:
        logger.exception("Training job %s failed", job_id)
        trainer.finish(
            TrainingJob.Status.FAILED,
            reason="The trainer failed unexpectedly; the "
            "error is in the worker's log. Your last checkpoint is kept.",
        )
    return True


class Trainer:
    """A training job's run on a trainer: the learner, the loop that gathers its workers'
    episodes and updates the policy from them, the clock, and the job's end."""

    def __init__(self, job: TrainingJob, start_rollouts, queued_rollouts=None) -> None:
        self.job = job
        self.model: RLModel = job.model
        self.start_rollouts = start_rollouts
        self.queued_rollouts = queued_rollouts or (lambda job: None)
        self.channel = JobChannel(redis_client(timeout=30.0), job.pk)
        self.ppo = self.model.algorithm == hp.PPO
        self.slots = [Slot(0, self.model.track.name)] + [
            Slot(i, name) for i, name in enumerate(self.model.extra_tracks, start=1)
        ]
        self.slots += [
            Slot(i, self.model.track.name) for i in range(len(self.slots), self.model.workers)
        ]
        # What it learns with (``_build_learner``), and the weights the workers drive
        self.learner: Learner | None = None
        self.spaces: tuple = ()  # the environment's observation and action spaces
        self.version = job.weights_version  # of the weights published to the workers
        # What came in
        self.collected: list[Episode] = []  # episodes of the iteration being gathered
        self.metrics: list[dict] = []
        self.evaluations: dict[int, list[dict]] = {}  # version: the results come so far
        self.printed: int | None = None  # lines of the workers and the reward function filed
        # The clock: billed from when a car drives (``_start_clock``), never while it waits
        self.base_seconds = job.training_seconds  # the time used before this run
        self.session_started: float | None = None  # when this run's clock started [monotonic]
        self.waiting_since = time.monotonic()  # for its first simulation worker
        self.first_run = job.started_at is None
        self.training_message = ""  # what the job's page says while it trains
        self.stopwatch = Stopwatch()  # where the time goes, by phase
        # How it ends
        self.ending: str | None = None  # why the loop ends: "stop" or "limit"
        self.abandoned: int | None = None  # the iteration an ending cut short
        # What it does every so often
        self.stop_looks = Every(STOP_CHECK)  # for the racer's stop and the time limit
        self.renewals = Every(CHECK_EVERY)  # of the lease, with the clock written
        self.worker_checks = Every(CHECK_EVERY)  # the workers, their logs and evaluations
        self.episodes_told = Every(EPISODES_TOLD_EVERY)  # the page's Progress line, as cars end

    # The loop

    def train(self) -> None:
        job, model = self.job, self.model
        preparing = not job.stop_requested and leases.move(
            job,
            TrainingJob.Status.INITIALIZING,
            started_at=job.started_at or timezone.now(),
            message="Preparing the trainer",
        )
        if not preparing:  # the racer stopped it before this run took it up, or as it did
            leases.log(job, "Stopped by the racer.")
            self.finish(TrainingJob.Status.COMPLETED)
            return
        # never back from STOPPING: a stop that lands now wins
        lifecycle.MODEL.move(model.pk, RLModel.Status.TRAINING)
        streams.announce_training(job.pk)
        streams.announce_queue()
        self._build_learner()
        self.version = job.weights_version
        self.channel.start(job.attempt)
        self._publish()
        for slot in self.slots:
            self.start_rollouts(job, slot)
        self.waiting_since = time.monotonic()
        self.training_message = f"Training with {_workers(len(self.slots))} on {self._tracks()}"
        self.base_seconds = job.training_seconds
        waiting = leases.clock_write(job, self.base_seconds, message=WAITING_FOR_WORKER)
        streams.announce_training(job.pk)
        if not waiting:  # the racer stopped it while it was being prepared
            leases.log(job, "Stopped by the racer.")
            self.finish(TrainingJob.Status.COMPLETED)
            return
        self._loop()
        self.finish(TrainingJob.Status.COMPLETED)

    def _start_clock(self) -> None:
        """Start the job's clock, and move it IN_PROGRESS, once the car drives: when one of its
        rollout workers beats (it beats before its first episode, through it, and while it
        waits for new weights) or an episode arrives. Until then the job is INITIALIZING,
        waiting for a simulation worker (the simulation queue may be busy with other jobs'
        rollouts and evaluations), and its clock stands still: the racer is never billed for
        time the job could not drive, as DeepRacer bills a job from when it trains, not while it
        waits. The clock starts when the trainer sees the beat, within a turn of it (about a
        second): any error is the racer's gain. It stops again whenever no car drives
        (``_stop_clock``)."""
        job = self.job
        self.session_started = time.monotonic()
        # the log says training started as the status does, never after a page saw the status
        with transaction.atomic():
            started = leases.clock_write(
                job,
                self.base_seconds,
                to=TrainingJob.Status.IN_PROGRESS,
                message=self.training_message,
            )
            if started and self.first_run:
                self.first_run = False  # said once, not each time the clock starts again
                device = "the GPU" if self.learner.device.startswith("cuda") else "the CPU"
                leases.log(
                    job,
                    f"Training started: {self.model.get_algorithm_display()}, "
                    f"{_workers(len(self.slots))}, learning on {device}.",
                )
        streams.announce_training(job.pk)
        if not started:  # the racer stopped it while it waited
            self.ending = "stop"

    def _stop_clock(self, why: str) -> None:
        """Stop the job's clock while no car drives (its rollout workers all stopped answering
        and their replacements wait behind other work, or Redis restarted): the time so far is
        kept, the job is INITIALIZING and waits for a simulation worker again, unbilled, as it
        did for its first, and for ``WORKER_PATIENCE`` at most; the clock starts again at the
        next beat or episode."""
        if self.session_started is None:
            return
        self.base_seconds = self._spent()
        self.session_started = None
        self.waiting_since = time.monotonic()
        leases.log(self.job, f"{why}: the clock stops until a car drives again.")
        waiting = leases.clock_write(
            self.job,
            self.base_seconds,
            to=TrainingJob.Status.INITIALIZING,
            message=WAITING_FOR_WORKER,
        )
        streams.announce_training(self.job.pk)
        if not waiting:  # the racer stopped it
            self.ending = "stop"

    def _build_learner(self) -> None:
        """The learner, with the weights the job goes on from: its last checkpoint when it
        resumes, else its clone source's best or fresh ones (saved as iteration 0)."""
        job, model = self.job, self.model
        env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
        self.spaces = env.observation_space, env.action_space
        env.close()
        self.learner = Learner.for_model(
            model, env, seed=model.seed, precision=settings.PITLANE_TRAINER_PRECISION
        )
        if job.last_checkpoint:
            self.learner.restore(artifacts.read(job.last_checkpoint))
            self._recall_progress()
            leases.log(
                job,
                f"Resumed from the checkpoint of iteration {job.iterations} "
                f"(attempt {job.attempt}).",
            )
            return
        artifacts.write_model_files(model)
        cloned = artifacts.path(model, artifacts.CLONED_WEIGHTS)
        if model.cloned_from_id is not None and not default_storage.exists(cloned):
            with leases.lease_renewed(job):  # its request died before it copied them
                why = services.clone_weights_copy(model=model)
            if why is not None:
                raise JobFailed(services.CLONE_COPY_FAILED.format(why=why))
        if model.cloned_from_id is not None and default_storage.exists(cloned):
            self.learner.restore(artifacts.read(cloned))
            leases.log(job, "Starting from the weights of the model this one was cloned from.")
        self._checkpoint(0)

    def _tracks(self) -> str:
        """The tracks of the job's workers, by the names racers know them by."""
        names = {slot.track for slot in self.slots}
        shown = dict(Track.objects.filter(name__in=names).values_list("name", "display_name"))
        return ", ".join(sorted(shown.get(name, name) for name in names))

    def _loop(self) -> None:
        while True:
            try:
                if self._turn():
                    return
            except redis.RedisError as error:
                self._recover_redis(f"Lost Redis ({error})")

    def _turn(self) -> bool:
        """One turn of the loop: the periodic checks, the episodes that came, and an update when
        enough have; True when training should end."""
        job, model = self.job, self.model
        if self._should_end():
            self._say_why_it_ended()
            return True
        if self.worker_checks.due():
            if not self.channel.is_set_up(job.attempt):
                self._recover_redis("Redis restarted and lost the job's keys")
                return False
            failure = self.channel.failure()
            if failure:
                raise JobFailed(failure)
            self._watch_workers()
            self._file_logs()
            self._take_evaluations()
        self.stopwatch.charge(CHECKS)
        first = self.channel.wait_for_episode(wait=1.0)
        self.stopwatch.charge(DRIVING)
        payloads = [first, *self.channel.pop_episodes(limit=49)] if first is not None else []
        if self.session_started is None and (payloads or _driving(self.channel.heartbeats())):
            self._start_clock()
            if self.ending is not None:
                self._say_why_it_ended()
                return True
        for payload in payloads:
            episode = self._decode(payload)
            if episode is None or (self.ppo and episode.version != self.version):
                continue  # PPO learns on-policy: episodes of older weights are dropped
            self.collected.append(episode)
        self.stopwatch.charge(TRANSFER)
        if payloads and self.episodes_told.due():  # the Progress line follows the cars
            streams.announce_training(job.pk)
        wanted = model.hyperparameters["num_episodes_between_training"]
        if len(self.collected) >= wanted:
            # Exactly ``wanted`` episodes an iteration, as DeepRacer's workers play their shares
            # of it (simapp bundle/markov/rollout_worker.py:249-254 (01f5f01)): each iteration's
            # trace then numbers the same episodes, which its readers rely on. Episodes past
            # that are of the weights about to be replaced: PPO drops them, SAC keeps them.
            episodes, surplus = self.collected[:wanted], self.collected[wanted:]
            self.collected = [] if self.ppo else surplus
            if not self._update(episodes):
                self._say_why_it_ended()
                return True
        return False

    # The clock, the stop and the time limit

    def _spent(self) -> float:
        """The training time used so far [s], this run's and the runs' before it."""
        if self.session_started is None:
            return self.base_seconds
        return self.base_seconds + time.monotonic() - self.session_started

    def _should_end(self) -> bool:
        """Whether training should end now: the racer asked to stop, or the time is up. Looks at
        most once a second (in the middle of an update too), and renews the lease and writes the
        clock every few seconds."""
        if self.ending is not None or not self.stop_looks.due():
            return self.ending is not None
        max_seconds = self.model.max_minutes * 60
        spent = min(self._spent(), max_seconds)
        if self.renewals.due():
            leases.write(self.job, lease_expires=timezone.now() + leases.lease())
            if not leases.clock_write(self.job, spent):
                self.ending = "stop"
            streams.announce_training(self.job.pk)
        elif self._stop_requested():
            self.ending = "stop"
        if self.ending is None and spent >= max_seconds:
            self.ending = "limit"
        return self.ending is not None

    def _say_why_it_ended(self) -> None:
        job, model = self.job, self.model
        if self.ending == "stop":
            leases.log(job, "Stopped by the racer.")
        else:
            leases.log(job, f"Reached the maximum training time of {model.max_minutes} min.")
        if self.abandoned is not None:
            leases.log(
                job,
                f"Iteration {self.abandoned} was being learnt and was abandoned; the model is "
                f"saved from iteration {self.abandoned - 1}.",
            )

    def _recover_redis(self, what: str) -> None:
        """Wait for Redis to come back, then set the job's keys up again and restart the rollout
        workers (who stop when Redis goes); ``JobFailed`` if it stays away."""
        leases.log(self.job, f"{what}; waiting for it.", "warning")
        self._stop_clock("Redis was lost")
        deadline = time.monotonic() + REDIS_PATIENCE
        while True:
            try:
                self.channel.client.ping()
                break
            except redis.RedisError:
                if time.monotonic() > deadline:
                    raise JobFailed(
                        f"Redis stayed unreachable for {REDIS_PATIENCE:.0f} s; training stopped. "
                        "Your last checkpoint is kept."
                    ) from None
                time.sleep(1.0)
        self.channel.start(self.job.attempt)
        self._publish()
        for slot in self.slots:
            if not slot.gone:
                slot.started, slot.started_wall = time.monotonic(), time.time()
                self.start_rollouts(self.job, slot)
        leases.log(
            self.job, "Redis is back: the experience buffer starts again from the newest weights."
        )

    def _update(self, episodes: list[Episode]) -> bool:
        """Learn one iteration from ``episodes`` and record it; False when training ended
        meanwhile (the racer stopped it, or its time ran out) and the iteration was abandoned."""
        number = self.version + 1
        progress = self._update_progress(number, episodes)
        share_cores(self.job.pk)
        self.stopwatch.charge(CHECKS)
        try:
            update = self.learner.learn(episodes, interrupted=self._should_end, progress=progress)
        except Interrupted:
            self.abandoned = number
            return False
        self.stopwatch.charge(UPDATE)
        self.version = number
        self._publish(evaluate=self.model.evaluation_trials)
        self.stopwatch.charge(TRANSFER)
        checkpoint = self._checkpoint(number)  # file work: before the transaction, not in it
        with transaction.atomic():
            row = Iteration.objects.create(
                job=self.job,
                number=number,
                reward=update.reward,
                completion=update.completion,
                best_lap_time=update.best_lap_time,
                episodes=update.episodes,
                steps=update.steps,
                wall_seconds=0.0,  # until the iteration is over, below
                training_points=[
                    [round(float(e.rewards.sum()), 3), round(float(e.progress), 2)]
                    for e in episodes
                ],
            )
            leases.write(
                self.job,
                weights_version=self.version,
                iterations=number,
                episodes=self.job.episodes + update.episodes,
                steps=self.job.steps + update.steps,
                last_checkpoint=checkpoint,
            )
        self._record_training(number, episodes)
        self.stopwatch.charge(SAVING)
        leases.clock_write(self.job, self._spent(), message=self.training_message)
        self.stopwatch.charge(CHECKS)
        split = self.stopwatch.take()
        wall = sum(split.values())
        Iteration.objects.filter(pk=row.pk).update(wall_seconds=wall, time_split=split)
        streams.announce_iteration(self.job.pk, number)
        streams.announce_training(self.job.pk)
        leases.log(
            self.job,
            f"Iteration {number}: {update.episodes} episodes, {update.steps} steps, "
            f"average progress {update.completion:.1f}%, {wall:.1f} s: "
            + ", ".join(f"{phase} {split[phase]:.1f} s" for phase in PHASES),
        )
        return True

    def _update_progress(self, number: int, episodes: list[Episode]) -> Progress:
        """The learner's word of how far the update of iteration ``number`` has gone, turned into
        the job's message (``update_message``) for the page, said now and every
        ``UPDATE_SAID_EVERY`` at most."""
        epochs = self.model.hyperparameters["num_epochs"] if self.ppo else 0
        about = f"iteration {number}, from {len(episodes)} episode{'s' * (len(episodes) > 1)}"
        estimate, said = UpdateEstimate(), [-UPDATE_SAID_EVERY]

        def progress(done: int, total: int) -> None:
            now = time.monotonic()
            left = estimate.report(done, total, now)
            if done == 0 or (done < total and now - said[0] >= UPDATE_SAID_EVERY):
                said[0] = now
                message = update_message(done, total, epochs, left, about)
                leases.clock_write(self.job, self._spent(), message=message)
                streams.announce_training(self.job.pk)

        progress(0, sum(e.steps for e in episodes))
        return progress

    def _publish(self, evaluate: int = 0) -> None:
        self.channel.publish(
            self.version,
            self.learner.policy_weights(),
            evaluate=evaluate,
            episodes=self.model.hyperparameters["num_episodes_between_training"],
        )

    def _recall_progress(self) -> None:
        """On resuming: the metrics written so far."""
        metrics = artifacts.path(self.model, artifacts.TRAINING_METRICS)
        if default_storage.exists(metrics):
            self.metrics = json.loads(artifacts.read(metrics))["metrics"]

    # Checkpoints, metrics, traces

    def _checkpoint(self, number: int) -> str:
        name = artifacts.save(self.model, artifacts.checkpoint(number), self.learner.checkpoint())
        if number == 0:
            leases.write(
                self.job, last_checkpoint=name, best_checkpoint=self.job.best_checkpoint or name
            )
        return name

    def _record_training(self, number: int, episodes: list[Episode]) -> None:
        before = self.job.episodes - len(episodes)  # training episodes of earlier iterations
        self.metrics += training_metrics(episodes, before=before, now=time.time())
        self._save_metrics()
        trace = training_trace(episodes, before=before)
        artifacts.save(self.model, artifacts.training_trace(number), trace)
        signals.trace_recorded.send(TrainingJob, document=trace, job=self.job, iteration=number)

    def _save_metrics(self) -> None:
        document = metrics_document(self.metrics, self.model.best_checkpoint_by)
        artifacts.save(self.model, artifacts.TRAINING_METRICS, document)

    def _take_evaluations(self) -> None:
        by_version: dict[int, list[dict]] = {}
        for payload in self.channel.pop_evaluations():
            try:
                result = unpack(payload)
                version = int(result["version"])
                progress = min(max(float(result["progress"]), 0.0), 100.0)
            except (ValueError, KeyError, TypeError):
                continue
            lap, seconds = result.get("lap_time"), result.get("seconds")
            reward = result.get("reward")
            by_version.setdefault(version, []).append(
                {
                    "progress": progress,
                    "reward": float(reward) if isinstance(reward, int | float) else 0.0,
                    "lap_time": float(lap) if isinstance(lap, int | float) else None,
                    "status": str(result.get("status", ""))[:20],
                    "steps": int(result.get("steps", 0)),
                    "seconds": float(seconds) if isinstance(seconds, int | float) else 0.0,
                }
            )
        # An evaluation's episodes come one at a time, beside the next iteration's: it is
        # recorded once all are in (one cut short by the end of training never is).
        for version, results in by_version.items():
            pending = self.evaluations.setdefault(version, [])
            pending += results
            if len(pending) >= self.model.evaluation_trials:
                self._record_evaluation(version, self.evaluations.pop(version))

    def _record_evaluation(self, version: int, results: list[dict]) -> None:
        row = Iteration.objects.filter(job=self.job, number=version).first()
        if row is None:
            return
        Iteration.objects.filter(pk=row.pk).update(
            **checkpoints.evaluation_means(results),
            evaluation_points=[round(r["progress"], 2) for r in results],
            evaluation_seconds=round(sum(r["seconds"] for r in results), 3),
        )
        streams.announce_iteration(self.job.pk, version)
        learnt_from = Iteration.objects.filter(job=self.job, number__lte=version).aggregate(
            total=Sum("episodes")
        )["total"]
        self.metrics = with_evaluation(
            self.metrics, evaluation_metrics(results, now=time.time()), episodes=learnt_from or 0
        )
        self._save_metrics()
        # DeepRacer's best model by the model's metric, over every iteration evaluated so far
        # (ours may come out of order, where simapp's come in order): checkpoints.best_iteration.
        evaluated = Iteration.objects.filter(job=self.job)
        best = checkpoints.best_iteration(rows=evaluated, metric=self.model.best_checkpoint_by)
        name = artifacts.path(self.model, artifacts.checkpoint(best.number)) if best else ""
        if name and name != self.job.best_checkpoint:
            leases.write(self.job, best_checkpoint=name)

    # Workers and the racer

    def _watch_workers(self) -> None:
        """Replace each rollout worker that died, up to ``REPLACEMENTS`` times a slot; carry on
        without a slot replaced that often, and fail the job when none is left.

        Since it was last (re)started, a slot's rollout is waiting, starting or driving:

        - waiting: no simulation worker has taken its task yet. The simulation queue may be busy
          (other jobs' rollouts, evaluations, races) for as long as their work lasts: a task
          waiting there is not dead, and a replacement would only queue behind it. It is given
          up only when it is no longer in the broker's queue yet no worker took it,
          ``PITLANE_ROLLOUT_STARTUP`` after it was sent (lost with a Redis restart, or held by
          a worker that died before it began); when the broker cannot say, after that alone.
        - starting: a worker took it (``JobChannel.take``) and loads the simulator and the
          sandbox; dead when it has not beaten ``PITLANE_ROLLOUT_STARTUP`` after that.
        - driving: it beats; dead when silent ``PITLANE_ROLLOUT_SILENCE``.

        When none of them has beaten for ``PITLANE_ROLLOUT_SILENCE``, no car drives: the clock
        stops (``_stop_clock``). A job none of whose rollouts drives ``WORKER_PATIENCE`` after
        they were sent, or after its cars last drove, fails, unbilled for the wait, rather than
        hold its trainer for ever (trainers and rollouts sharing one pool that the trainers
        fill; no worker serving the simulation queue).
        """
        beats, takings = self.channel.heartbeats(), self.channel.takings()
        if not _driving(beats):
            self._stop_clock("No simulation worker is driving")
        if self.session_started is None and time.monotonic() - self.waiting_since > WORKER_PATIENCE:
            raise JobFailed(NO_WORKER)
        queued = functools.cache(lambda: self.queued_rollouts(self.job) or set())  # read once
        for slot in self.slots:
            why = None if slot.gone else _why_dead(slot, beats, takings, queued)
            if why is None:
                continue
            now, wall = time.monotonic(), time.time()
            if slot.replacements < REPLACEMENTS:
                slot.replacements += 1
                slot.started, slot.started_wall = now, wall
                what = why.format(worker=f"Simulation worker {slot.index + 1}")
                leases.log(self.job, f"{what}; starting a replacement.", "warning")
                self.start_rollouts(self.job, slot)
            else:
                slot.gone = True
                left = sum(not s.gone for s in self.slots)
                if left == 0:
                    raise JobFailed(
                        "Every simulation worker stopped answering; check that a "
                        "worker serves the simulation queue."
                    )
                message = f"Carrying on with {left} of {len(self.slots)} simulation workers"
                leases.log(self.job, message + ".", "warning")
                leases.write(self.job, message=message)

    def _stop_requested(self) -> bool:
        return TrainingJob.objects.filter(pk=self.job.pk, stop_requested=True).exists()

    def _file_logs(self) -> None:
        """File what the workers sent for the log: their messages, and what the reward function
        printed (each worker keeps a bounded share of it per iteration); past
        ``MAX_PRINTED_LINES`` in the job's log, the rest is dropped, and the log says so once."""
        entries = self.channel.pop_log()
        if not entries:
            return
        if self.printed is None:
            self.printed = self.job.log_lines.exclude(source=JobLogLine.Source.TRAINER).count()
        room = MAX_PRINTED_LINES - self.printed
        kept = entries[: max(room, 0)]
        JobLogLine.objects.bulk_create(
            JobLogLine(job=self.job, source=entry.source, level=entry.level, text=entry.text)
            for entry in kept
        )
        self.printed += len(kept)
        if len(kept) < len(entries) and room >= 0:
            self.printed += 1  # said once
            leases.log(
                self.job,
                f"The log holds {MAX_PRINTED_LINES:,} lines from the simulation workers and the "
                "reward function; later ones are not kept.",
                "warning",
            )

    def _decode(self, payload: bytes) -> Episode | None:
        try:
            return decode_episode(payload, *self.spaces, ppo=self.ppo)
        except ValueError as error:
            leases.log(self.job, f"An episode was malformed and was dropped: {error}", "warning")
            return None

    # The end

    def finish(self, status: str, reason: str = "") -> None:
        """End the job: the clock stops (where the racer's stop froze it, or at the time used, up
        to the limit), the workers are told to stop, and the model is saved from its last
        finished iteration."""
        job = self.job
        try:
            self.channel.request_stop()
            self.channel.expire()
            self._file_logs()
        except redis.RedisError:
            pass
        try:
            if self.session_started is not None:
                leases.clock_write(job, min(self._spent(), self.model.max_minutes * 60))
            message = leases.saving_message(job.iterations)
            leases.move(job, TrainingJob.Status.STOPPING, message=message)
            if status == TrainingJob.Status.COMPLETED:
                artifacts.write_model_files(self.model)
            leases.move(
                job,
                status,
                finished_at=timezone.now(),
                failure_reason=reason,
                message="",
                lease_expires=None,
            )
        except LeaseLost:
            return
        if reason:
            leases.log(job, reason, "error")
        has_checkpoint = bool(job.last_checkpoint)
        ready = status == TrainingJob.Status.COMPLETED or has_checkpoint
        lifecycle.MODEL.move(self.model.pk, RLModel.Status.READY if ready else RLModel.Status.ERROR)
        streams.announce_training(job.pk)
        notifications.training_ended(job=job)


# The files DeepRacer's tools read


def training_metrics(episodes: list[Episode], *, before: int, now: float) -> list[dict]:
    """One iteration's training episodes as DeepRacer's metrics JSON lists them (simapp
    bundle/markov/metrics/s3_metrics.py:315-329 (01f5f01)): ``episode`` counts the job's
    training episodes from 1, ``trial`` counts them within the iteration from 1, the reward is
    rounded to a whole number, the completion truncated, the status labelled ("Lap complete").
    Times are in ms; ours are the wall clock's, DeepRacer's the simulator's."""
    return [
        _metric(
            "training",
            steps=episode.steps,
            reward=round(float(episode.rewards.sum())),
            progress=episode.progress,
            status=episode.status,
            now=now,
            episode=before + offset + 1,
            trial=offset + 1,
        )
        for offset, episode in enumerate(episodes)
    ]


def evaluation_metrics(results: list[dict], *, now: float) -> list[dict]:
    """The evaluation episodes of one policy, in the same form (no reward: the evaluation drives
    no reward function); ``episode`` and ``trial`` are set by ``with_evaluation``."""
    return [
        _metric(
            "evaluation",
            steps=result["steps"],
            reward=0,
            progress=result["progress"],
            status=result["status"],
            now=now,
            episode=0,
            trial=0,
        )
        for result in results
    ]


def _metric(
    phase: str,
    *,
    steps: int,
    reward: int,
    progress: float,
    status: str,
    now: float,
    episode: int,
    trial: int,
) -> dict:
    """One entry of DeepRacer's metrics JSON: the episode's time is its steps at the control
    rate, ending ``now``; the completion is truncated to a whole percentage."""
    elapsed = round(steps * 1000 / CONTROL_HZ)
    return {
        "reward_score": reward,
        "metric_time": int(now * 1000),
        "start_time": int(now * 1000) - elapsed,
        "elapsed_time_in_milliseconds": elapsed,
        "episode": episode,
        "trial": trial,
        "phase": phase,
        "completion_percentage": int(min(max(float(progress), 0.0), 100.0)),
        "episode_status": artifacts.status_label(status),
    }


def with_evaluation(metrics: list[dict], evaluation: list[dict], *, episodes: int) -> list[dict]:
    """``metrics`` with the evaluation of the policy learnt from the first ``episodes`` training
    episodes placed after them. As in DeepRacer's file, evaluation entries repeat the ``episode``
    and ``trial`` of the last training episode before them (simapp
    bundle/markov/metrics/s3_metrics.py:316-317, 399-406 (01f5f01)), which is how its readers
    (deepracer-utils' TrainingMetrics) put them in their iteration."""
    position, last = 0, {"episode": 0, "trial": 0}
    for index, entry in enumerate(metrics):
        if entry["episode"] > episodes:
            break
        position = index + 1
        if entry["phase"] == "training":
            last = entry
    placed = [{**entry, "episode": last["episode"], "trial": last["trial"]} for entry in evaluation]
    return metrics[:position] + placed + metrics[position:]


def metrics_document(metrics: list[dict], best_model_metric: str = "progress") -> str:
    """The training metrics file, naming the metric that picks the best checkpoint: simapp
    bundle/markov/metrics/s3_metrics.py:351-353 and bundle/markov/constants.py:16 (01f5f01)."""
    return json.dumps({"metrics": metrics, "version": 2.0, "best_model_metric": best_model_metric})


def training_trace(episodes: list[Episode], *, before: int) -> str:
    """One iteration's simulation trace: each episode's rows, numbered as DeepRacer numbers its
    training episodes, from 0 over the whole job (simapp bundle/markov/metrics/s3_metrics.py:
    316, 381-382 (01f5f01)). The workers share one experience buffer, so the episodes of all
    workers are in one file, numbered in the order the trainer learnt from them: no two of an
    iteration share a number."""
    rows = [
        SimTraceRow(*row)._replace(episode=before + offset)
        for offset, episode in enumerate(episodes)
        for row in episode.trace
        if len(row) == 19
    ]
    return to_csv(rows)


def _driving(beats: dict[int, float]) -> bool:
    """Whether one of the job's rollout workers has beaten (``beats``: their last beats, [s since
    the epoch]) within ``PITLANE_ROLLOUT_SILENCE``: a car drives."""
    return time.time() - max(beats.values(), default=0.0) <= settings.PITLANE_ROLLOUT_SILENCE


def _why_dead(slot: Slot, beats: dict[int, float], takings: dict[int, float], queued) -> str | None:
    """Why the rollout of ``slot`` is taken for dead, in the racer's words, ``{worker}`` for the
    worker's name; None while it lives or waits (``Trainer._watch_workers`` says when). ``beats``
    and ``takings`` are the slots' last beats and takes [s since the epoch]; ``queued()`` the
    slots whose task waits in the broker's queue, read only for a rollout that has waited past
    its startup bound."""
    wall = time.time()
    last, taken = beats.get(slot.index, 0.0), takings.get(slot.index, 0.0)
    if last >= slot.started_wall:  # driving
        return (
            "{worker} stopped answering" if wall - last > settings.PITLANE_ROLLOUT_SILENCE else None
        )
    if taken >= slot.started_wall:  # starting
        late = wall - taken > settings.PITLANE_ROLLOUT_STARTUP
        return "{worker} stopped answering as it started" if late else None
    waited = time.monotonic() - slot.started > settings.PITLANE_ROLLOUT_STARTUP
    if waited and slot.index not in queued():
        return "{worker}'s task was lost from the queue before any worker took it"
    return None


def _workers(count: int) -> str:
    return f"{count} simulation worker{'s' if count != 1 else ''}"


class UpdateEstimate:
    """The time a policy update has left, from the pace of its gradient steps (PPO's minibatches,
    SAC's steps), as the learner reports them done.

    The pace counts from the first step reported, not from the update's start: the rollout's copy
    to the device and its advantages come once, before it, and would make every step look as
    slow. The time is said once the pace is measured over ``SETTLED`` of the steps or
    ``SETTLED_AFTER`` seconds: before that, the first step's warm-up and the steps a GPU has
    queued but not yet run would set it. And it never rises within the update: a slower stretch
    holds it where it was rather than turning it back up."""

    SETTLED = 0.1  # of the update's steps done, or
    SETTLED_AFTER = 2.0  # [s] since the first, before the time left is said

    def __init__(self) -> None:
        self.first: tuple[int, float] | None = None  # (steps done, [s] monotonic) when first told
        self.left: float | None = None  # [s] the least said so far

    def report(self, done: int, total: int, now: float) -> float | None:
        """[s] left after ``done`` of ``total`` steps at ``now`` (``time.monotonic()``); None
        while it is too soon to say, and once the update is done."""
        if not 0 < done < total:
            return None
        if self.first is None:
            self.first = (done, now)
        steps, seconds = done - self.first[0], now - self.first[1]
        if steps <= 0 or (done < self.SETTLED * total and seconds < self.SETTLED_AFTER):
            return self.left
        pace = seconds / steps * (total - done)
        self.left = pace if self.left is None else min(self.left, pace)
        return self.left


def update_message(done: int, total: int, epochs: int, left: float | None, about: str) -> str:
    """What the racer reads while the policy is updated: ``done`` of ``total`` gradient steps, in
    epochs of ``epochs`` (PPO) or in steps (SAC, ``epochs`` 0), with the time ``left`` [s]
    (``UpdateEstimate``) where it can be said; ``about``: which iteration, from what."""
    if epochs:
        where = f"epoch {min(done * epochs // max(total, 1) + 1, epochs)} of {epochs}"
    else:
        where = f"{done:,} of {total:,} gradient steps"
    left_words = f", about {clock(left)} left" if left is not None and 0 < done < total else ""
    return f"Updating the policy: {where}{left_words} ({about})"
