"""A rollout worker: the loop of the ``training.rollout`` task, one per simulation slot of a job.

It starts a sandbox child that holds the simulator, the policy network and the racer's reward
function, keeps the child's weights at the newest published version, and relays what the child
drives: training episodes to the experience buffer, evaluation results after each update, and
what the reward function printed. It never writes the job's rows; a failure of the racer's code
is reported to the trainer, which fails the job.
"""

from __future__ import annotations

import logging
import time

import msgpack
import redis

from console.workers import redis_client
from training import hyperparameters as hp
from training import live
from training.experience import JobChannel
from training.models import TrainingJob
from training.sandbox import MiB, Sandbox, SandboxFailure, SandboxUnavailable, verified

logger = logging.getLogger(__name__)

REWARD_CALL_LIMIT = 1.0  # [s]
WAIT_POLL = 0.2  # [s] between looks for new weights while the trainer learns
JOB_CHECK = 15.0  # [s] between looks at the job's row
MEMORY_ALLOWANCE = 1024 * MiB  # beyond the child's size with torch and the simulator loaded
HOLD_INTERVAL = 1.0  # [s] between the paused frames shown while the trainer learns


def run(job_id: int, worker: int, attempt: int, track: str) -> None:
    job = TrainingJob.objects.select_related("model").filter(pk=job_id).first()
    if job is None or not job.is_active or job.attempt != attempt:
        logger.info("Rollout %s/%s is stale or its job ended; nothing to do", job_id, worker)
        return
    model = job.model
    channel = JobChannel(redis_client(timeout=30.0), job_id)
    try:
        verified()
    except SandboxUnavailable as error:
        channel.report_failure(str(error))
        return
    policy = {"algorithm": model.algorithm, "network": model.network, "seed": model.seed + worker}
    try:
        with Sandbox(
            env=model.environment_settings(track), policy=policy,
            call_timeout=REWARD_CALL_LIMIT, memory_allowance=MEMORY_ALLOWANCE,
        ) as sandbox:  # fmt: skip
            sandbox.load(model.reward_function)
            with live.FramePublisher(channel.client, live.training_group(job_id)) as publisher:
                _drive(sandbox, channel, job, worker, Viewing(sandbox, publisher, worker))
    except SandboxFailure as failure:
        channel.report_failure(f"Your reward function failed {_where(failure, worker)}: {failure}")
    except redis.RedisError as error:
        logger.warning("Rollout %s/%s lost Redis: %s", job_id, worker, error)


class Viewing:
    """A rollout worker's side of live viewing: it tells its sandbox which views someone watches,
    relays the frames the sandbox sends, and shows the car waiting while the trainer learns."""

    def __init__(self, sandbox: Sandbox, publisher: live.FramePublisher, worker: int) -> None:
        self.sandbox, self.publisher, self.worker = sandbox, publisher, worker
        self.views: set[str] = set()
        self.last: dict[str, dict] = {}
        self.held = 0.0
        sandbox.on_frame = self.relay

    def update(self) -> None:
        views = self.publisher.watched(self.worker)
        if views != self.views:
            self.sandbox.watch(views)
            self.views = views

    def relay(self, raw: dict) -> None:
        frame = live.frame_from_child(raw, self.worker)
        if frame is not None:
            self.last[frame["view"]] = frame
            self.publisher.offer(frame)

    def hold(self) -> None:
        """The last frames again, marked paused, once a second: the viewer sees the car wait for
        the new policy, not a stream that stalled, and an unchanging picture costs the server
        one frame a second rather than fifteen."""
        if time.monotonic() - self.held < HOLD_INTERVAL:
            return
        self.held = time.monotonic()
        for view in self.views:
            if view in self.last:
                self.publisher.offer({**self.last[view], "paused": True,
                                      "rendered_at": time.time()})  # fmt: skip


def _drive(
    sandbox: Sandbox, channel: JobChannel, job: TrainingJob, worker: int, viewing: Viewing
) -> None:
    algorithm, attempt = job.model.algorithm, job.attempt
    version = -1
    evaluated = -1
    checked = time.monotonic()

    def beat(steps: int) -> None:  # a long episode still shows the trainer this worker lives
        channel.beat(worker)
        viewing.update()

    while not channel.should_stop(attempt):
        channel.beat(worker)
        viewing.update()
        if time.monotonic() - checked > JOB_CHECK:
            checked = time.monotonic()
            if not _still_wanted(job):
                return
        published = channel.policy_version()
        if published > version:
            published, weights = channel.fetch_policy()
            sandbox.set_weights(published, weights)
            version = published
        if worker == 0 and version > 0 and evaluated < version:
            for _ in range(channel.evaluations_wanted()):
                summary = sandbox.episode("evaluate", worker, beat)["summary"]
                channel.push_evaluation(msgpack.packb({**summary, "version": version}))
                channel.beat(worker)
            evaluated = version
            continue
        mode = "random" if version == 0 and algorithm == hp.SAC else "explore"
        reply = sandbox.episode(mode, worker, beat)
        channel.push_episode(reply["payload"])
        channel.push_log(list(sandbox.logs))
        sandbox.logs.clear()
        if channel.count_episode(version) >= channel.episodes_wanted():
            _await_next_version(channel, version, worker, attempt, viewing)


def _still_wanted(job: TrainingJob) -> bool:
    """Whether the job is still running under this attempt (its trainer may have died, or the job
    been deleted, without a word to Redis)."""
    return TrainingJob.objects.filter(
        pk=job.pk, attempt=job.attempt, status__in=TrainingJob.ACTIVE
    ).exists()


def _await_next_version(
    channel: JobChannel, version: int, worker: int, attempt: int, viewing: Viewing
) -> None:
    """The trainer has the episodes it wants of this version: wait while it learns, rather than
    drive episodes it would drop (and take the CPU it learns with)."""
    while channel.policy_version() <= version and not channel.should_stop(attempt):
        channel.beat(worker)
        viewing.update()
        viewing.hold()
        time.sleep(WAIT_POLL)


def _where(failure: SandboxFailure, worker: int) -> str:
    return (
        f"in simulation worker {worker + 1}" if failure.step is None else f"(worker {worker + 1})"
    )
