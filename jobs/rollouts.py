"""A rollout worker: the loop of the ``training.rollout`` task, one per simulation slot of a job.

It starts a sandbox child that holds the simulator (``PITLANE_CARS_PER_WORKER`` cars, driven
together) and the racer's reward function, keeps the child's weights at the newest published
version, and relays what the child drives. The cars' policy is served by the machine's policy
server (``rl.policy_server``, ``PITLANE_ROLLOUT_DEVICE``), which this worker opens the child's
slots in and gives the weights (the child, which runs racers' code, is given its slots alone and
never the GPU); or, with "child", it runs in the child. It relays
training episodes to the experience buffer as each car ends one, evaluation results after each
update, and what the reward function printed. It never writes the job's rows; a failure of the
racer's code is reported to the trainer, which fails the job.

Long because a rollout worker's loop and its ways out (new weights, a stop, a sandbox that
died, a lost Redis, a policy server that went away) are one state machine, read together.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable

import msgpack
import redis
from django.conf import settings

from common.redis_client import redis_client
from jobs.shares import rollout_niceness
from rl import hyperparameters as hp
from rl.experience import JobChannel, LogEntry
from rl.policy_lease import PolicyLease
from rl.weights_cache import WeightsCache
from sandbox import MiB, Sandbox, SandboxFailure, SandboxUnavailable, verified
from training import streams
from training.models import Track, TrainingJob

logger = logging.getLogger(__name__)

REWARD_CALL_LIMIT = 1.0  # [s]
WAIT_POLL = 0.2  # [s] between looks for new weights while the trainer learns
JOB_CHECK = 15.0  # [s] between looks at the job's row
MEMORY_ALLOWANCE = 1024 * MiB  # beyond the child's size with torch and the simulator loaded
CAR_MEMORY = 384 * MiB  # more per car past the first: a 10,000-step episode of stereo frames
HOLD_INTERVAL = 1.0  # [s] between the paused frames shown while the trainer learns
STOP_LOOK = 1.0  # [s] between looks for the end of the job in the middle of an episode
PRINTED_LINES = 20  # lines of what the reward function printed a worker keeps per iteration
PRINTED_CHARACTERS = 4000  # and characters of them


class JobEnded(Exception):
    """The trainer ended the job while an episode was being driven: the episode is abandoned."""


class EndWatch:
    """Raises ``JobEnded`` once the trainer has ended the job's run (``JobChannel.should_stop``),
    looking in Redis at most once per ``STOP_LOOK``: called as an episode drives (its progress
    messages come every 0.25 s)."""

    def __init__(self, channel: JobChannel, run: str) -> None:
        self.channel, self.run = channel, run
        self.looked = time.monotonic()

    def __call__(self) -> None:
        if time.monotonic() - self.looked >= STOP_LOOK:
            self.looked = time.monotonic()
            if self.channel.should_stop(self.run):
                raise JobEnded


def run(job_id: int, worker: int, attempt: int, track: str) -> None:
    channel = JobChannel(redis_client(timeout=30.0), job_id)
    token = channel.join(attempt)  # the run this worker drives in; it stops when that ends
    if token is None:
        logger.info("Rollout %s/%s found no run of attempt %s going on", job_id, worker, attempt)
        return
    channel.take(worker)  # before the slower reads: a task just dequeued is never taken for lost
    job = TrainingJob.objects.select_related("model").filter(pk=job_id).first()
    if job is None or not job.is_active or job.attempt != attempt:
        logger.info("Rollout %s/%s is stale or its job ended; nothing to do", job_id, worker)
        return
    model = job.model
    name = f"Simulation worker {worker + 1}"
    try:
        verified()
    except SandboxUnavailable as error:
        channel.report_failure(str(error))
        return
    # the job's share of the machine against the others' (jobs.shares), as the worker starts
    sandbox = _sandboxes(model, job_id, worker, track, rollout_niceness(job_id))
    label = name if model.workers > 1 else ""
    printed = Printed(label)
    try:
        with contextlib.ExitStack() as stack:
            driver = stack.enter_context(sandbox(cars_for(model.algorithm)))
            driver.load(model.reward_function)
            evaluator = None
            if worker == 0:  # DeepRacer's first worker evaluates (simapp
                # bundle/markov/rollout_worker.py:327-329, 01f5f01)
                evaluator = CheckpointEvaluator(
                    stack.enter_context(sandbox(model.evaluation_trials, in_turn=True)),
                    channel,
                    token,
                    Printed(label),
                )
                evaluator.sandbox.load(model.reward_function)
                stack.callback(evaluator.close)
            shown = Track.objects.filter(name=track).values_list("display_name", flat=True)
            where = _served_words(driver)
            driving = f"{name} is driving {shown.first() or track}{where}."
            channel.push_log([LogEntry("worker", driving)])
            with streams.FramePublisher(
                channel.client, streams.training_group(job_id)
            ) as publisher:
                viewing = Viewing(driver, publisher, worker)
                try:
                    why = _drive(driver, channel, token, job, worker, viewing, printed, evaluator)
                except JobEnded:
                    why = "the training ended; the episode it was driving was abandoned"
                channel.push_log([*printed.close(), LogEntry("worker", f"{name} stopped: {why}.")])
    except SandboxFailure as failure:
        channel.report_failure(failure_words(failure, worker))
    except redis.RedisError as error:
        logger.warning("Rollout %s/%s lost Redis: %s", job_id, worker, error)


def cars_for(algorithm: str) -> int:
    """The cars a worker's sandbox drives: ``PITLANE_CARS_PER_WORKER``, but one for SAC, which
    wants one episode per update and would never start a second car (so would build seven
    environments, and take their memory, for nothing)."""
    return 1 if algorithm == hp.SAC else settings.PITLANE_CARS_PER_WORKER


def _sandboxes(
    model, job_id: int, worker: int, track: str, niceness: int = 0
) -> Callable[..., Sandbox]:
    """The worker's sandboxes, of so many cars, each driving with ``model``'s policy: served by
    the machine's policy server, unless ``PITLANE_ROLLOUT_DEVICE`` keeps it in the child."""
    policy = {
        "algorithm": model.algorithm,
        "architecture": model.architecture,
        "seed": model.seed + worker * cars_for(model.algorithm),  # car k takes this + k
        "job": job_id,
    }
    device = settings.PITLANE_ROLLOUT_DEVICE

    def sandbox(cars: int, in_turn: bool = False) -> Sandbox:
        served = device != "child"
        return Sandbox(
            env=model.environment_settings(track),
            cars=cars,
            in_turn=in_turn,
            policy=policy,
            policy_lease=PolicyLease(settings.PITLANE_POLICY_SOCKET, device) if served else None,
            call_timeout=REWARD_CALL_LIMIT,
            memory_allowance=MEMORY_ALLOWANCE,
            car_memory=CAR_MEMORY,
            niceness=niceness,
        )

    return sandbox


def _served_words(sandbox: Sandbox) -> str:
    """Where the cars' policy runs, for the worker's first log line."""
    lease = sandbox.policy_lease
    if lease is None:
        return ""
    where = "the GPU" if lease.served_on.startswith("cuda") else "the CPU"
    return f", its cars' policy served by the machine's policy server on {where}"


class Viewing:
    """A rollout worker's side of live viewing: it tells its sandbox which views someone watches,
    relays the frames the sandbox sends, and shows the car waiting while the trainer learns."""

    def __init__(self, sandbox: Sandbox, publisher: streams.FramePublisher, worker: int) -> None:
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
        frame = streams.frame_from_child(raw, self.worker)
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
                self.publisher.offer(
                    {**self.last[view], "paused": True, "rendered_at": time.time()}
                )

    def resume(self) -> None:
        """The pause is over: frames flow from the sandbox again."""
        self.shown = None


class CheckpointEvaluator:
    """The first worker's evaluations, in a sandbox of their own, on a thread of their own: the
    evaluation episodes of checkpoint N drive while the training episodes of iteration N + 1 do,
    rather than in turn with them (DeepRacer's first worker drives them after its share of an
    iteration's episodes, while the trainer learns: simapp bundle/markov/rollout_worker.py:
    327-329, 01f5f01), and the trainer marks the best checkpoint when their results come. The
    episodes drive together, a car each, from the starts one car would take in turn
    (``Sandbox.in_turn``): their steps share the policy's passes (beside the training cars' where
    the policy is served), so the evaluation ends within the iteration's driving rather than
    running on into the update, whose CPU it would take. The newest checkpoint is evaluated: one
    that a newer replaced while an evaluation ran is not. A failure of the racer's code here
    fails the job as it would in training: ``check`` raises it on the worker's own thread."""

    def __init__(self, sandbox: Sandbox, channel: JobChannel, run: str, printed: Printed):
        self.sandbox, self.channel, self.printed = sandbox, channel, printed
        self.evaluated = 0  # the newest version evaluated or being evaluated; 0 is never
        self.thread: threading.Thread | None = None
        self.failure: BaseException | None = None
        self.ending = threading.Event()
        self.job_ended = EndWatch(channel, run)

    def offer(self, version: int, weights: bytes) -> None:
        """Evaluate ``version`` (its ``weights``) unless it has been or one runs still."""
        self.check()
        if version <= self.evaluated or (self.thread is not None and self.thread.is_alive()):
            return
        self.evaluated = version
        episodes = self.channel.evaluations_wanted()
        self.thread = threading.Thread(
            target=self._evaluate,
            args=(version, weights, episodes),
            name=f"evaluation of {version}",
            daemon=True,
        )
        self.thread.start()

    def check(self) -> None:
        """Raise what ended the last evaluation, if it failed."""
        failure, self.failure = self.failure, None
        if failure is not None:
            raise failure

    def close(self) -> None:
        """Abandon the evaluation under way (within a progress message, 0.25 s) and wait for it."""
        self.ending.set()
        if self.thread is not None:
            self.thread.join()

    def _evaluate(self, version: int, weights: bytes, episodes: int) -> None:
        """Drive ``episodes`` with ``version``'s weights, a car each while there are cars, and
        push each result as its car ends, with the wall-clock ``seconds`` since the last (the
        results' sum is the evaluation's time)."""
        try:
            self.sandbox.set_weights(version, weights)
            waiting, driving = episodes, 0
            last = time.monotonic()
            for _ in range(episodes):
                start = min(self.sandbox.cars - driving, waiting)
                reply = self.sandbox.episode("evaluate", 0, self._beat, start=start)
                waiting, driving = waiting - start, reply["driving"]
                now = time.monotonic()
                seconds, last = round(now - last, 3), now
                self.channel.push_evaluation(
                    msgpack.packb({**reply["summary"], "version": version, "seconds": seconds})
                )
                self.channel.push_log(self.printed.take(self.sandbox, version + 1))
            self.channel.push_log(self.printed.close())
        except JobEnded:
            pass
        except Exception as error:  # the worker's thread raises it: see ``check``
            self.failure = error

    def _beat(self, steps: int) -> None:
        if self.ending.is_set():
            raise JobEnded
        self.job_ended()


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
        return [
            LogEntry(
                "reward",
                f"… {dropped:,} more line{'s' if dropped != 1 else ''} "
                f"printed{who} in iteration {self.iteration} not kept",
            )
        ]


def _drive(
    sandbox: Sandbox,
    channel: JobChannel,
    run: str,
    job: TrainingJob,
    worker: int,
    viewing: Viewing,
    printed: Printed,
    evaluator: CheckpointEvaluator | None = None,
) -> str:
    """Drive episodes until the job's run ends; why it ended, in the racer's words.

    The sandbox's cars drive together, and each episode goes to the buffer as it ends. A car
    starts another only for an episode reserved in Redis (``JobChannel.episodes_reserve``):
    while the version it drives with is the newest and the episodes pushed of it and those under
    way on every worker come short of what the trainer wants. With one car, one episode after
    another until the trainer has its share, as a single car always drove. The weights change
    only once no car drives, so no episode mixes two versions; and none is started that the
    trainer would drop for being past its count (it keeps the first to come, and those would
    be the short ones)."""
    algorithm = job.model.algorithm
    version = -1
    weights = b""
    checked = time.monotonic()
    job_ended = EndWatch(channel, run)
    driving = 0  # cars under way
    channel.reservations_drop(worker)  # a predecessor's, if it died driving: never to come

    def beat(steps: int) -> None:  # a long episode still shows the trainer this worker lives
        channel.beat(worker)
        viewing.update()
        job_ended()

    while not channel.should_stop(run):
        channel.beat(worker)
        viewing.update()
        if time.monotonic() - checked > JOB_CHECK:
            checked = time.monotonic()
            if not _still_wanted(job):
                return "the training is over"
        published = channel.policy_version()
        if driving == 0 and published > version:
            version, weights = channel.fetch_policy(WeightsCache(settings.PITLANE_WEIGHTS_CACHE))
            sandbox.set_weights(version, weights)
        if evaluator is not None and version > 0:
            evaluator.offer(version, weights)
        mode = "random" if version == 0 and algorithm == hp.SAC else "explore"
        start = channel.episodes_reserve(worker, version, sandbox.cars - driving)
        if driving == 0 and start == 0:  # the rest of the version's are pushed or under way
            channel.push_log(printed.close())  # this worker's share of the iteration is done
            if not _await_next_version(channel, run, job, version, worker, viewing, evaluator):
                return "the training is over"
            continue
        reply = sandbox.episode(mode, worker, beat, start=start)
        driving = reply["driving"]
        channel.push_episode(reply["payload"], version, worker)
        channel.push_log(printed.take(sandbox, version + 1))
    return "the training ended"


def _still_wanted(job: TrainingJob) -> bool:
    """Whether the job is still running under this attempt (its trainer may have died, or the job
    been deleted, without a word to Redis)."""
    return TrainingJob.objects.filter(
        pk=job.pk, attempt=job.attempt, status__in=TrainingJob.ACTIVE
    ).exists()


def _await_next_version(
    channel: JobChannel,
    run: str,
    job: TrainingJob,
    version: int,
    worker: int,
    viewing: Viewing,
    evaluator: CheckpointEvaluator | None = None,
) -> bool:
    """The trainer has the episodes it wants of this version: wait while it learns, rather than
    drive episodes it would drop (and take the CPU it learns with). False when the job's row says
    it is over: a trainer that died, or a job deleted, without a word to Redis would otherwise
    leave this worker waiting for ever, holding a place in the pool."""
    checked = time.monotonic()
    while channel.policy_version() <= version and not channel.should_stop(run):
        if time.monotonic() - checked > JOB_CHECK:
            checked = time.monotonic()
            if not _still_wanted(job):
                return False
        channel.beat(worker)
        viewing.update()
        viewing.hold()
        if evaluator is not None:
            evaluator.check()
        time.sleep(WAIT_POLL)
    viewing.resume()
    return True


def failure_words(failure: SandboxFailure, worker: int) -> str:
    """What the job's failure says of ``failure`` in ``worker``: the racer's code's, or (its
    policy failing on its device, its simulator missing PyBullet) the worker's own."""
    if failure.kind in ("policy", "simulation"):
        return f"Simulation worker {worker + 1} failed (not your reward function): {failure}"
    return f"Your reward function failed {_where(failure, worker)}: {failure}"


def _where(failure: SandboxFailure, worker: int) -> str:
    car = f", car {failure.car + 1}" if failure.car is not None and failure.step is not None else ""
    return (
        f"in simulation worker {worker + 1}"
        if failure.step is None
        else f"(worker {worker + 1}{car})"
    )
