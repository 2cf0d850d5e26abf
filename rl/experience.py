"""The Redis side of a training job: the experience buffer, the published policy and control.

Keys belong to one job and expire after it ends:
``pitlane:job:<id>:experience`` (a list of episodes), ``pitlane:job:<id>:counts`` (a hash:
the training episodes pushed per policy version), ``pitlane:job:<id>:reserved`` (a hash: per
rollout worker, "version:count" of the episodes it has started and not yet pushed),
``pitlane:job:<id>:evaluation`` (a list of evaluation results), ``pitlane:job:<id>:policy``
(a hash: version, weights, their size and hash) and ``pitlane:job:<id>:control`` (a hash:
stop, attempt, the run's token, and when each rollout worker took its task and last beat).
Episodes travel as msgpack with their arrays as raw bytes: they come from a sandbox that ran a
racer's code, so the trainer checks every field before it learns from one (``decode_episode``).

Long because the keys are one protocol between the trainer and its workers: each side's reads
and writes of them, and the checks of what a sandbox sent, are read together.
"""

from __future__ import annotations

import json
import secrets
import time
from dataclasses import dataclass

import numpy as np
import redis

from rl.weights_cache import Published, WeightsCache, weights_digest
from rl.wire import decode, decode_array
from simulator.rewards import MAX_REWARD

EXPIRE_AFTER = 3600  # [s] the keys live after the job ends
MAX_QUEUED_EPISODES = 2000  # the buffer is trimmed beyond this, oldest first
MAX_LOG_LINES = 500  # log lines waiting for the trainer to file them
MAX_LOG_TEXT = 500  # [characters] of one log line
LOG_SOURCES = ("worker", "reward")  # JobLogLine.Source values a rollout worker may send
LOG_LEVELS = ("info", "warning", "error")
# Reserve up to ARGV[3] episodes of version ARGV[2] for worker ARGV[1], as many as the trainer
# still wants of it past those pushed and those other workers (and this one) drive; none of a
# version no longer the newest. One script, so two workers never both take the last ones.
RESERVE = """
local version = redis.call('HGET', KEYS[1], 'version')
if version ~= ARGV[2] then return 0 end
local room = tonumber(redis.call('HGET', KEYS[1], 'episodes') or '1')
room = room - tonumber(redis.call('HGET', KEYS[2], version) or '0')
local mine = 0
local held = redis.call('HGETALL', KEYS[3])
for i = 1, #held, 2 do
  local of, count = string.match(held[i + 1], '^(%-?%d+):(%d+)$')
  if of == version then
    room = room - tonumber(count)
    if held[i] == ARGV[1] then mine = tonumber(count) end
  end
end
local granted = math.max(0, math.min(tonumber(ARGV[3]), room))
redis.call('HSET', KEYS[3], ARGV[1], version .. ':' .. (mine + granted))
redis.call('EXPIRE', KEYS[3], ARGV[4])
return granted
"""
# Worker ARGV[1] pushed an episode of version ARGV[2]: one fewer it holds reserved.
UNRESERVE = """
local of, count = string.match(redis.call('HGET', KEYS[1], ARGV[1]) or '', '^(%-?%d+):(%d+)$')
if of == ARGV[2] and tonumber(count) > 0 then
  redis.call('HSET', KEYS[1], ARGV[1], of .. ':' .. (tonumber(count) - 1))
end
return 0
"""


@dataclass(frozen=True)
class LogEntry:
    """A line for the job's log from a rollout worker: its own message (``source`` "worker"), or
    what the reward function printed ("reward")."""

    source: str
    text: str
    level: str = "info"


def key(job_id: int, part: str) -> str:
    return f"pitlane:job:{job_id}:{part}"


class JobChannel:
    """One job's keys in Redis."""

    def __init__(self, client: redis.Redis, job_id: int) -> None:
        self.client = client
        self.job_id = job_id
        self.experience = key(job_id, "experience")
        self.counts = key(job_id, "counts")
        self.reserved = key(job_id, "reserved")
        self.evaluation = key(job_id, "evaluation")
        self.policy = key(job_id, "policy")
        self.control = key(job_id, "control")
        self.log = key(job_id, "log")

    # Policy

    def publish(self, version: int, weights: bytes, *, episodes: int, evaluate: int = 0) -> None:
        """Weights ``version``, and how many training episodes the trainer wants with it. Their
        size and hash go beside them: a machine's ``WeightsCache`` names and checks its copy so."""
        self.client.hset(
            self.policy,
            mapping={
                "version": version,
                "weights": weights,
                "evaluate": evaluate,
                "episodes": episodes,
                "size": len(weights),
                "digest": weights_digest(weights),
            },
        )

    def policy_version(self) -> int:
        value = self.client.hget(self.policy, "version")
        return int(value) if value is not None else -1

    def fetch_policy(self, cache: WeightsCache | None = None) -> tuple[int, bytes]:
        """The newest weights published: (version, weights); (-1, b"") before any. With a
        ``cache``, from this machine's copy, fetched from Redis by the first of its workers to
        need them (the others wait for that one fetch): once per machine, not per worker."""
        if cache is not None:
            published = self._published()
            if published is not None:
                return cache.weights(self.job_id, published, self._fetch_published)
        version, weights = self.client.hmget(self.policy, "version", "weights")
        if version is None:
            return -1, b""
        return int(version), weights

    def _published(self) -> Published | None:
        """What names the newest weights, without them; None before any (or from a trainer
        that published none of it)."""
        version, size, digest = self.client.hmget(self.policy, "version", "size", "digest")
        if version is None or size is None or digest is None:
            return None
        return Published(int(version), int(size), digest.decode())

    def _fetch_published(self) -> tuple[Published, bytes]:
        version, digest, weights = self.client.hmget(self.policy, "version", "digest", "weights")
        if version is None or weights is None:
            raise redis.RedisError("the published weights vanished (the job's keys expired)")
        digest = digest.decode() if digest is not None else weights_digest(weights)
        return Published(int(version), len(weights), digest), weights

    def evaluations_wanted(self) -> int:
        """How many evaluation episodes the trainer asks for with the current version."""
        return int(self.client.hget(self.policy, "evaluate") or 0)

    # Experience

    def episodes_reserve(self, worker: int, version: int, most: int) -> int:
        """How many episodes of ``version`` (at most ``most``) ``worker`` may start: those the
        trainer still wants past the ones pushed and the ones every worker has reserved and not
        pushed; none once a newer version is published. The trainer keeps the first episodes of
        a version to come, so an episode started past its count would be dropped, and those
        dropped would be the longest (the laps completed): a bias the reservations prevent."""
        return int(
            self.client.eval(
                RESERVE,
                3,
                self.policy,
                self.counts,
                self.reserved,
                worker,
                version,
                most,
                EXPIRE_AFTER,
            )
        )

    def reservations_drop(self, worker: int) -> None:
        """Give back what ``worker`` reserved and did not push: its episodes were abandoned
        (a worker that died mid-episode, now replaced), and another may drive them."""
        self.client.hdel(self.reserved, str(worker))

    def push_episode(self, payload: bytes, version: int, worker: int | None = None) -> int:
        """A training episode driven with ``version`` into the buffer (by ``worker``, for one of
        its reservations); how many of that version's have been pushed so far. The episode and
        its count go in one transaction, and ``start`` deletes both in one: a worker that
        outlived a Redis restart, whose client retries its push on the new server, cannot leave
        a count the buffer does not hold (the other workers would stop short of the episodes
        the trainer waits for)."""
        pipe = self.client.pipeline(transaction=True)
        pipe.rpush(self.experience, payload)
        pipe.ltrim(self.experience, -MAX_QUEUED_EPISODES, -1)
        pipe.hincrby(self.counts, str(version), 1)
        pipe.expire(self.counts, EXPIRE_AFTER)
        if worker is not None:
            pipe.eval(UNRESERVE, 1, self.reserved, worker, version)
        return pipe.execute()[2]

    def wait_for_episode(self, wait: float) -> bytes | None:
        """The oldest episode in the buffer, waiting at most ``wait`` seconds for one."""
        first = self.client.blpop([self.experience], timeout=wait)
        return None if first is None else first[1]

    def pop_episodes(self, limit: int) -> list[bytes]:
        """Up to ``limit`` more of the episodes in the buffer, without waiting."""
        return list(self.client.lpop(self.experience, limit) or [])

    def push_evaluation(self, payload: bytes) -> None:
        self.client.rpush(self.evaluation, payload)

    def pop_evaluations(self) -> list[bytes]:
        return list(self.client.lpop(self.evaluation, 100) or [])

    # Control

    def start(self, attempt: int) -> None:
        """The job's keys, as new: nothing buffered or counted, and a run of ``attempt`` begun,
        under a token of its own. The trainer starts one when the job starts and again when Redis
        comes back from a restart; rollout workers join the run going when they start
        (``join``), and one that outlived a restart sees the token change and stops, rather
        than drive on beside its replacement."""
        pipe = self.client.pipeline(transaction=True)
        pipe.delete(
            self.experience, self.counts, self.reserved, self.evaluation, self.control, self.log
        )
        pipe.hset(
            self.control,
            mapping={
                "stop": 0,
                "attempt": attempt,
                "run": f"{attempt}:{secrets.token_hex(8)}",
            },
        )
        pipe.execute()

    def is_set_up(self, attempt: int) -> bool:
        """Whether the job's control keys are there (a restarted Redis has lost them)."""
        return self.join(attempt) is not None

    def join(self, attempt: int) -> str | None:
        """The token of the run of ``attempt`` going on, for a rollout worker to drive in; None
        when none is."""
        current, run = self.client.hmget(self.control, "attempt", "run")
        if current != str(attempt).encode() or run is None:
            return None
        return run.decode()

    def request_stop(self) -> None:
        self.client.hset(self.control, "stop", 1)

    def should_stop(self, run: str) -> bool:
        """Whether a rollout worker of ``run`` should stop: the trainer asked, or the run is over
        (its job's keys are gone, or a new run began)."""
        stop, current = self.client.hmget(self.control, "stop", "run")
        return stop == b"1" or current is None or current.decode() != run

    def beat(self, worker: int) -> None:
        self.client.hset(self.control, f"worker:{worker}", time.time())

    def take(self, worker: int) -> None:
        """A rollout worker's word that it took its task and is starting (loading the simulator
        and the sandbox, before its first beat): its slot no longer waits in the broker's queue."""
        self.client.hset(self.control, f"taken:{worker}", time.time())

    def heartbeats(self) -> dict[int, float]:
        """When each rollout worker last beat, by slot [s since the epoch]."""
        return self._marks(b"worker:")

    def takings(self) -> dict[int, float]:
        """When each slot's task was last taken by a rollout worker [s since the epoch]."""
        return self._marks(b"taken:")

    def _marks(self, prefix: bytes) -> dict[int, float]:
        return {
            int(name.split(b":")[1]): float(value)
            for name, value in self.client.hgetall(self.control).items()
            if name.startswith(prefix)
        }

    def report_failure(self, message: str) -> None:
        """A rollout worker's word that the racer's code failed; the trainer fails the job."""
        self.client.hsetnx(self.control, "failure", message[:1000])

    def failure(self) -> str | None:
        value = self.client.hget(self.control, "failure")
        return value.decode("utf-8", "replace") if value else None

    def push_log(self, entries: list[LogEntry]) -> None:
        """Lines for the job's log; the list keeps the newest ``MAX_LOG_LINES`` until filed."""
        if entries:
            pipe = self.client.pipeline()
            pipe.rpush(
                self.log,
                *[
                    json.dumps([entry.source, entry.level, entry.text[:MAX_LOG_TEXT]])
                    for entry in entries
                ],
            )
            pipe.ltrim(self.log, -MAX_LOG_LINES, -1)
            pipe.execute()

    def pop_log(self) -> list[LogEntry]:
        entries = []
        for raw in self.client.lpop(self.log, MAX_LOG_LINES) or []:
            try:
                source, level, text = json.loads(raw)
            except (ValueError, TypeError):
                continue
            if source in LOG_SOURCES and level in LOG_LEVELS and isinstance(text, str):
                entries.append(LogEntry(source, text[:MAX_LOG_TEXT], level))
        return entries

    def expire(self) -> None:
        for name in (
            self.experience,
            self.counts,
            self.reserved,
            self.evaluation,
            self.policy,
            self.control,
            self.log,
        ):
            self.client.expire(name, EXPIRE_AFTER)


# Episodes


@dataclass
class Episode:
    """One episode of experience, checked."""

    worker: int
    version: int
    observations: dict[str, np.ndarray]  # each (steps + 1, ...): the last is the final state
    actions: np.ndarray
    rewards: np.ndarray
    values: np.ndarray | None  # PPO's value estimates, (steps,)
    log_probs: np.ndarray | None  # PPO's, (steps,)
    terminated: bool  # ended by the environment (off track, lap complete, ...)
    final_value: float  # the value of the final state, for a truncated episode
    progress: float
    status: str
    lap_time: float | None
    trace: list

    @property
    def steps(self) -> int:
        return len(self.rewards)


def decode_episode(payload: bytes, observation_space, action_space, ppo: bool) -> Episode:
    """An episode from a rollout worker, every field checked; ValueError for anything amiss."""
    message = decode(payload)  # ProtocolError, a ValueError, when it is no message
    arrays = message.get("arrays") or {}
    rewards = decode_array(arrays.get("rewards"), "float32", (None,))
    steps = len(rewards)
    if not 1 <= steps <= 10_000:
        raise ValueError(f"an episode of {steps} steps")
    if not np.isfinite(rewards).all() or np.abs(rewards).max() > MAX_REWARD:
        raise ValueError("rewards out of range")
    observations = {}
    for name, space in observation_space.spaces.items():
        observation = decode_array(
            arrays.get(f"obs:{name}"), str(space.dtype), (steps + 1, *space.shape)
        )
        if observation.dtype.kind == "f" and not np.isfinite(observation).all():
            raise ValueError(f"{name} observations out of range")
        observations[name] = observation
    if hasattr(action_space, "n"):
        actions = decode_array(arrays.get("actions"), "int64", (steps,))
        if actions.min() < 0 or actions.max() >= action_space.n:
            raise ValueError("actions out of range")
    else:
        actions = decode_array(arrays.get("actions"), "float32", (steps, *action_space.shape))
        if not np.isfinite(actions).all():
            raise ValueError("actions out of range")
    values = log_probs = None
    if ppo:
        values = decode_array(arrays.get("values"), "float32", (steps,))
        log_probs = decode_array(arrays.get("log_probs"), "float32", (steps,))
        if not (np.isfinite(values).all() and np.isfinite(log_probs).all()):
            raise ValueError("values out of range")
    final_value = float(message.get("final_value", 0.0))
    progress = float(message.get("progress", 0.0))
    if not (np.isfinite(final_value) and 0.0 <= progress <= 100.0):
        raise ValueError("summary out of range")
    lap_time = message.get("lap_time")
    return Episode(
        worker=int(message.get("worker", 0)),
        version=int(message.get("version", -1)),
        observations=observations,
        actions=actions,
        rewards=rewards,
        values=values,
        log_probs=log_probs,
        terminated=bool(message.get("terminated")),
        final_value=final_value,
        progress=progress,
        status=str(message.get("status", ""))[:20],
        lap_time=float(lap_time) if isinstance(lap_time, int | float) and lap_time > 0 else None,
        trace=list(message.get("trace") or [])[:10_001],
    )
