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
from training.experience import JobChannel, LogEntry
from training.models import Track, TrainingJob
from training.sandbox import MiB, Sandbox, SandboxFailure, SandboxUnavailable, verified

logger = logging.getLogger(__name__)

REWARD_CALL_LIMIT = 1.0  # [s]
WAIT_POLL = 0.2  # [s] between looks for new weights while the trainer learns
JOB_CHECK = 15.0  # [s] between looks at the job's row
MEMORY_ALLOWANCE = 1024 * MiB  # beyond the child's size with torch and the simulator loaded
HOLD_INTERVAL = 1.0  # [s] between the paused frames shown while the trainer learns
STOP_LOOK = 1.0  # [s] between looks for the end of the job in the middle of an episode
PRINTED_LINES = 20  # lines of what the reward function printed a worker keeps per iteration
PRINTED_CHARACTERS = 4000  # and characters of them


class JobEnded(Exception):
    """The trainer ended the job while an episode was being driven: the episode is abandoned."""


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
    policy = {
        "algorithm": model.algorithm,
        "architecture": model.architecture,
        "seed": model.seed + worker,
    }
    name = f"Simulation worker {worker + 1}"
    printed = Printed(name if model.workers > 1 else "")
    try:
        with Sandbox(
            env=model.environment_settings(track), policy=policy,
            call_timeout=REWARD_CALL_LIMIT, memory_allowance=MEMORY_ALLOWANCE,
        ) as sandbox:  # fmt: skip
            sandbox.load(model.reward_function)
            shown = Track.objects.filter(name=track).values_list("display_name", flat=True)
            channel.push_log([LogEntry("worker", f"{name} is driving {shown.first() or track}.")])
            with live.FramePublisher(channel.client, live.training_group(job_id)) as publisher:
                try:
                    why = _drive(sandbox, channel, job, worker, Viewing(sandbox, publisher, worker),
                                 printed)  # fmt: skip
                except JobEnded:
                    why = "the training ended; the episode it was driving was abandoned"
                channel.push_log([*printed.close(), LogEntry("worker", f"{name} stopped: {why}.")])
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
        self.shown: set[str] | None = None  # while holding: the views drawn since it began
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
            if self.shown is None:
                self.publisher.offer(frame)

    def hold(self) -> None:
        """The last frames again, marked paused, once a second: the viewer sees the car wait for
        the new policy, not a stream that stalled, and an unchanging picture costs the server
        one frame a second rather than fifteen. A view not yet drawn since the pause began
        (the viewer chose it meanwhile) is drawn at once, as the car stands."""
        if self.shown is None:
            self.shown = set()
        unseen = self.views - self.shown
        if not unseen and time.monotonic() - self.held < HOLD_INTERVAL:
            return
        if unseen:
            self.sandbox.show(unseen)
            self.shown |= unseen
        self.held = time.monotonic()
        for view in self.views:
            if view in self.last:
                self.publisher.offer({**self.last[view], "paused": True,
                                      "rendered_at": time.time()})  # fmt: skip

    def resume(self) -> None:
        """The pause is over: frames flow from the sandbox again."""
        self.shown = None


class Printed:
    """What the reward function printed, as a worker files it: per iteration, the first
    ``PRINTED_LINES`` lines (``PRINTED_CHARACTERS`` at most); the rest is counted, and a note
    says how many lines were not kept once the iteration is over. ``label``: who printed, where
    several workers do."""

    def __init__(self, label: str = "") -> None:
        self.label = label
        self.iteration = 0
        self.kept = self.characters = self.dropped = 0

    def take(self, sandbox: Sandbox, iteration: int) -> list[LogEntry]:
        """The log entries for what ``sandbox`` printed since the last take, driving for
        ``iteration``."""
        lines, dropped = sandbox.take_logs()
        entries = self.close() if iteration != self.iteration else []
        self.iteration = iteration
        for line in lines:
            if self.kept < PRINTED_LINES and self.characters + len(line) <= PRINTED_CHARACTERS:
                entries.append(LogEntry("reward", f"{self.label}: {line}" if self.label else line))
                self.kept += 1
                self.characters += len(line)
            else:
                self.dropped += 1
        self.dropped += dropped
        return entries

    def close(self) -> list[LogEntry]:
        """The note of the lines the iteration printed and were not kept, if any."""
        dropped, self.kept, self.characters, self.dropped = self.dropped, 0, 0, 0
        if not dropped:
            return []
        who = f" by {self.label.lower()}" if self.label else ""
        return [LogEntry("reward", f"… {dropped:,} more line{'s' if dropped != 1 else ''} "
                         f"printed{who} in iteration {self.iteration} not kept")]  # fmt: skip


def _drive(
    sandbox: Sandbox, channel: JobChannel, job: TrainingJob, worker: int, viewing: Viewing,
    printed: Printed,
) -> str:  # fmt: skip
    """Drive episodes until the job ends; why it ended, in the racer's words."""
    algorithm, attempt = job.model.algorithm, job.attempt
    version = -1
    evaluated = -1
    checked = looked = time.monotonic()

    def beat(steps: int) -> None:  # a long episode still shows the trainer this worker lives
        nonlocal looked
        channel.beat(worker)
        viewing.update()
        if time.monotonic() - looked >= STOP_LOOK:
            looked = time.monotonic()
            if channel.should_stop(attempt):
                raise JobEnded

    while not channel.should_stop(attempt):
        channel.beat(worker)
        viewing.update()
        if time.monotonic() - checked > JOB_CHECK:
            checked = time.monotonic()
            if not _still_wanted(job):
                return "the training is over"
        published = channel.policy_version()
        if published > version:
            published, weights = channel.fetch_policy()
            sandbox.set_weights(published, weights)
            version = published
        if worker == 0 and version > 0 and evaluated < version:
            for _ in range(channel.evaluations_wanted()):
                summary = sandbox.episode("evaluate", worker, beat)["summary"]
                channel.push_evaluation(msgpack.packb({**summary, "version": version}))
                channel.push_log(printed.take(sandbox, version + 1))
                channel.beat(worker)
            evaluated = version
            continue
        mode = "random" if version == 0 and algorithm == hp.SAC else "explore"
        reply = sandbox.episode(mode, worker, beat)
        channel.push_episode(reply["payload"])
        channel.push_log(printed.take(sandbox, version + 1))
        if channel.count_episode(version) >= channel.episodes_wanted():
            channel.push_log(printed.close())  # this worker's share of the iteration is done
            if not _await_next_version(channel, job, version, worker, viewing):
                return "the training is over"
    return "the training ended"


def _still_wanted(job: TrainingJob) -> bool:
    """Whether the job is still running under this attempt (its trainer may have died, or the job
    been deleted, without a word to Redis)."""
    return TrainingJob.objects.filter(
        pk=job.pk, attempt=job.attempt, status__in=TrainingJob.ACTIVE
    ).exists()


def _await_next_version(
    channel: JobChannel, job: TrainingJob, version: int, worker: int, viewing: Viewing
) -> bool:
    """The trainer has the episodes it wants of this version: wait while it learns, rather than
    drive episodes it would drop (and take the CPU it learns with). False when the job's row says
    it is over: a trainer that died, or a job deleted, without a word to Redis would otherwise
    leave this worker waiting for ever, holding a place in the pool."""
    checked = time.monotonic()
    while channel.policy_version() <= version and not channel.should_stop(job.attempt):
        if time.monotonic() - checked > JOB_CHECK:
            checked = time.monotonic()
            if not _still_wanted(job):
                return False
        channel.beat(worker)
        viewing.update()
        viewing.hold()
        time.sleep(WAIT_POLL)
    viewing.resume()
    return True


def _where(failure: SandboxFailure, worker: int) -> str:
    return (
        f"in simulation worker {worker + 1}" if failure.step is None else f"(worker {worker + 1})"
    )
