"""What the sandbox costs: `python -m bench.bench_sandbox` (or `make bench`).

The same loop twice, on one core: the simulator (camera on, centre-line driver) calling a typical
reward function (our "prevent zig-zag" example, which reads several params and branches), once in
this process and once inside a sealed sandbox child, where a rollout really runs. The sandbox adds
a timer around each reward call, seccomp's check of each syscall, and progress messages.
"""

from __future__ import annotations

import os
import statistics
import time

import gymnasium

import simulator
from sandbox import Sandbox
from simulator.controller import drive
from training.rewards import EXAMPLES

STEPS = 6000
ROUNDS = 3
TRACK = "rookie-loop"


def reward_source() -> str:
    return next(example for example in EXAMPLES if example.slug == "prevent_zig_zag").source


def in_process() -> float:
    namespace: dict = {}
    exec(compile(reward_source(), "<reward_function>", "exec"), namespace)  # noqa: S102
    env = gymnasium.make(simulator.ENV_ID, track=TRACK, reward_fn=namespace["reward_function"])
    env.reset(seed=0)
    drive(env, 300)  # warm-up
    started = time.perf_counter()
    drive(env, STEPS)
    elapsed = time.perf_counter() - started
    env.close()
    return STEPS / elapsed


def in_sandbox() -> float:
    with Sandbox(env={"track": TRACK}) as sandbox:
        sandbox.load(reward_source())
        sandbox.rollout(300)  # warm-up
        result = sandbox.rollout(STEPS)
    return result["steps"] / result["elapsed"]


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # the child inherits it
    direct = statistics.median(in_process() for _ in range(ROUNDS))
    sandboxed = statistics.median(in_sandbox() for _ in range(ROUNDS))
    print(f"{'loop':<46}{'steps/s':>10}")
    print(f"{'simulator + reward function, in process':<46}{direct:>10,.0f}")
    print(f"{'simulator + reward function, in the sandbox':<46}{sandboxed:>10,.0f}")
    print(f"{'cost of the sandbox':<46}{(1 - sandboxed / direct) * 100:>9.1f}%")


if __name__ == "__main__":
    main()
