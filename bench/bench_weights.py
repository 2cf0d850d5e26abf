"""The policy weights' trip through Redis each iteration, before and after a machine's rollout
workers shared one copy of them (``rl.weights_cache``): `python -m bench.bench_weights`.

A private Redis; the trainer's side publishes each iteration's weights (a real policy's, the
3-layer PPO of DeepRacer's defaults unless ``--architecture`` says otherwise) as
``JobChannel.publish`` does, and ``--workers`` W rollout workers, each a process of its own on
this machine, fetch them as ``jobs.rollouts._drive`` does: "before", each from Redis
(``fetch_policy()``), "after", through the machine's cache (``fetch_policy(cache)``). Per
iteration it prints the bytes Redis sent (its ``total_net_output_bytes``), the fan-out time (from
the end of the publish to the last worker holding the weights) and the publish's own time.

Per environment step: the weights Redis sent in an iteration over ``--steps`` steps an iteration
(4,379 by default: docs/benchmarks.md's iteration of a lapping car, DeepRacer's 20 episodes),
beside the experience's bytes a step, measured on episodes driven in the real simulator (the
camera's frames as the sandbox encodes them; each episode goes into Redis and out once, as the
trainer pops it). Workers on other machines each fetch once for theirs: the cache's figure is
per machine.
"""

from __future__ import annotations

import argparse
import multiprocessing
import statistics
import tempfile
import time
from pathlib import Path

import gymnasium
import msgpack
import redis

import simulator
from rl import episode
from rl.experience import JobChannel
from rl.hyperparameters import PPO
from rl.learner import weights_bytes
from rl.networks import SHALLOW
from rl.policies import Policy
from rl.weights_cache import WeightsCache
from rl.wire import encode_arrays
from tests.services import RedisServer

JOB = 1
TRACK = "rookie-loop"
LAPPING_STEPS = 4379  # an iteration of docs/benchmarks.md's throughput bench, the car lapping
EXPERIENCE_STEPS = 200  # [steps] driven to measure the experience's bytes a step


def _worker(url: str, cache: str | None, orders, done) -> None:
    """A rollout worker's fetches: at each order, the newest weights; its answer, when it holds
    them (``perf_counter``: one clock for every process of the machine)."""
    channel = JobChannel(redis.Redis.from_url(url, socket_timeout=60), JOB)
    shared = WeightsCache(cache) if cache is not None else None
    while orders.get() is not None:
        version, weights = channel.fetch_policy(shared)
        done.put((time.perf_counter(), version, len(weights)))


def fan_out(url: str, weights: bytes, workers: int, iterations: int, cache: str | None) -> dict:
    """[s] and [bytes] per iteration: W workers fetching each of ``iterations`` versions."""
    client = redis.Redis.from_url(url)
    channel = JobChannel(client, JOB)
    context = multiprocessing.get_context("fork")
    orders = [context.Queue() for _ in range(workers)]
    done = context.Queue()
    processes = [
        context.Process(target=_worker, args=(url, cache, order, done)) for order in orders
    ]
    for process in processes:
        process.start()
    sent, times, publishes = [], [], []
    try:
        for version in range(iterations):
            varied = weights[:-4] + version.to_bytes(4, "little")  # each version other bytes
            started = time.perf_counter()
            channel.publish(version, varied, episodes=20)
            published = time.perf_counter()
            before = client.info("stats")["total_net_output_bytes"]
            for order in orders:
                order.put(version)
            answers = [done.get(timeout=600) for _ in orders]
            assert all(got == version and size == len(weights) for _, got, size in answers)
            sent.append(client.info("stats")["total_net_output_bytes"] - before)
            times.append(max(at for at, _, _ in answers) - published)
            publishes.append(published - started)
    finally:
        for order in orders:
            order.put(None)
        for process in processes:
            process.join(30)
    return {
        "bytes": statistics.median(sent),
        "seconds": statistics.median(times),
        "publish": statistics.median(publishes),
    }


def experience_bytes_per_step() -> float:
    """[bytes] of the experience payload a step, as the sandbox child encodes its episodes."""
    env = gymnasium.make(simulator.ENV_ID, track=TRACK)
    policy = Policy.build(PPO, SHALLOW, env.observation_space, env.action_space)
    steps = size = 0
    seed = 0
    while steps < EXPERIENCE_STEPS:
        driven = episode.drive(env, policy, "explore", seed=seed)
        arrays = episode.experience(driven, discrete=True, ppo=True)
        payload = msgpack.packb(
            {"arrays": encode_arrays(arrays), "trace": driven.trace}, use_bin_type=True
        )
        steps, size, seed = steps + len(driven.rewards), size + len(payload), seed + 1
    env.close()
    return size / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 4, 8])
    parser.add_argument("--iterations", type=int, default=5)
    parser.add_argument("--steps", type=int, default=LAPPING_STEPS, help="steps an iteration")
    parser.add_argument("--architecture", default=SHALLOW)
    arguments = parser.parse_args()
    env = gymnasium.make(simulator.ENV_ID, track=TRACK)
    policy = Policy.build(PPO, arguments.architecture, env.observation_space, env.action_space)
    env.close()
    weights = weights_bytes(policy.weights_module.state_dict())
    experience = experience_bytes_per_step()
    print(
        f"Weights {len(weights) / 1e6:.1f} MB ({arguments.architecture}); experience "
        f"{experience / 1e3:.1f} kB a step, into Redis and out again: {2 * experience / 1e3:.1f} "
        f"kB a step; {arguments.steps:,} steps an iteration"
    )
    print(
        "| rollout workers on the machine | fetch | Redis sent per iteration | per step "
        "(weights + experience) | fan-out per iteration | publish |"
    )
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="pitlane-bench-weights-") as scratch:
        server = RedisServer(Path(scratch) / "redis")
        try:
            for workers in arguments.workers:
                caches = {
                    "each worker from Redis": None,
                    "the machine's cache": f"{scratch}/cache-{workers}",
                }
                for label, cache in caches.items():
                    got = fan_out(server.url, weights, workers, arguments.iterations, cache)
                    per_step = got["bytes"] / arguments.steps
                    print(
                        f"| {workers} | {label} | {got['bytes'] / 1e6:.1f} MB | "
                        f"{per_step / 1e3:.1f} + {2 * experience / 1e3:.1f} kB | "
                        f"{got['seconds'] * 1e3:.0f} ms | "
                        f"{got['publish'] * 1e3:.0f} ms |"
                    )
        finally:
            server.stop()


if __name__ == "__main__":
    main()
