"""The reward function's share of a step of several cars: `python -m bench.bench_reward_calls`.

A rollout's child asks its reward process (``sandbox.reward.RewardProcess``, sealed as in a
rollout) for each car's reward: once a car a step (``call``, as before issue 43) or once a step
for all the cars (``calls``). This times both for the same params (``--cars`` cars' first steps
on rookie-loop, DeepRacer's "prevent zig-zag" example), on one core as ``bench_sandbox`` runs the
child and its reward process, and prints the milliseconds a step of all the cars takes: wall
time, and the CPU time of this process (the child's part) and of the reward process.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from collections.abc import Callable

import gymnasium

import simulator
from bench.bench_sandbox import TRACK, reward_source
from sandbox import MiB
from sandbox.reward import RewardProcess

CARS = 8
STEPS = 2000
ROUNDS = 5


def step_params(cars: int) -> list[dict]:
    """The reward params of ``cars`` steps driven at random, one a car."""
    env = gymnasium.make(simulator.ENV_ID, track=TRACK)
    env.reset(seed=0)
    params = []
    for _ in range(cars):
        params.append(env.unwrapped.advance(env.action_space.sample()))
        env.unwrapped.conclude(0.0)
    env.close()
    return params


def cpu_seconds(pid: int) -> float:
    """[s] the user and system time process ``pid`` has taken."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def timed(step: Callable[[], object], pid: int, steps: int) -> tuple[float, float, float]:
    """[ms] a step's wall time, this process's CPU time and the reward process's."""
    step()  # warm-up (the waypoints sent)
    wall, mine, theirs = time.perf_counter(), time.process_time(), cpu_seconds(pid)
    for _ in range(steps):
        step()
    return (
        1000 * (time.perf_counter() - wall) / steps,
        1000 * (time.process_time() - mine) / steps,
        1000 * (cpu_seconds(pid) - theirs) / steps,
    )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cars", type=int, default=CARS, help="cars a step")
    parser.add_argument("--steps", type=int, default=STEPS, help="steps timed per figure")
    parser.add_argument("--rounds", type=int, default=ROUNDS, help="figures a median is of")
    options = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # the reward process's too
    params = step_params(options.cars)
    process = RewardProcess(1.0, 1024 * MiB)
    try:
        process.wait_ready(60.0)
        process.load(reward_source(), copies=options.cars)
        ways = {
            "a round trip a car (call)": lambda: [
                process.call(each, car=car) for car, each in enumerate(params)
            ],
            "one a step (calls)": lambda: process.calls(list(enumerate(params))),
        }
        figures: dict[str, list[tuple[float, float, float]]] = {name: [] for name in ways}
        for _ in range(options.rounds):  # alternated, so that a busy spell hits both
            for name, step in ways.items():
                figures[name].append(timed(step, process.pid, options.steps))
    finally:
        process.stop()
    cars = f"{options.cars} car{'s' if options.cars != 1 else ''}"
    print(f"{'ms a step of ' + cars:<36}{'wall':>8}{'child CPU':>11}{'reward CPU':>12}")
    for name, runs in figures.items():
        wall, mine, theirs = (statistics.median(column) for column in zip(*runs, strict=True))
        print(f"{name:<36}{wall:>8.3f}{mine:>11.3f}{theirs:>12.3f}")


if __name__ == "__main__":
    main()
