"""Simulator speed: `python -m bench.bench_simulator` (or `make bench`).

One process, one core: environment steps per second with the camera on (the centre-line driver,
the default reward function, every status and param computed), camera frames per second, and
spectator frames per second. DeepRacer's Gazebo simulation runs at 15 steps per second.
"""

from __future__ import annotations

import os
import time

import gymnasium

import simulator
from simulator.controller import CentreLineDriver

DEEPRACER_STEPS_PER_SECOND = 15
SECONDS = 3.0  # per measurement, after a warm-up


def rate(work, seconds: float = SECONDS) -> float:
    """Calls of ``work`` per second, measured for about ``seconds``."""
    for _ in range(50):
        work()
    count, started = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - started) < seconds:
        for _ in range(100):
            work()
        count += 100
    return count / elapsed


def environment_steps(**settings) -> float:
    env = gymnasium.make(simulator.ENV_ID, track="rookie-loop", **settings)
    env.reset(seed=0)
    driver = CentreLineDriver(env.unwrapped, speed=1.0)

    def step() -> None:
        _, _, terminated, truncated, _ = env.step(driver.act())
        if terminated or truncated:
            env.reset()

    result = rate(step)
    env.close()
    return result


def main() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, as promised
    env = gymnasium.make(simulator.ENV_ID, track="rookie-loop", render_mode="rgb_array")
    env.reset(seed=0)
    car = env.unwrapped
    camera = car._cameras[0]
    figures = [
        ("environment steps/s, camera, time trial", environment_steps()),
        ("environment steps/s, stereo + lidar, 3 bot cars",
         environment_steps(sensors=["STEREO_CAMERAS", "LIDAR"], race_type="HEAD_TO_BOT")),
        ("environment steps/s, camera, 3 boxes",
         environment_steps(race_type="OBJECT_AVOIDANCE")),
        ("camera frames/s (160 x 120 grayscale)",
         rate(lambda: camera.render(car.car.x, car.car.y, car.car.yaw))),
        ("spectator frames/s (640 x 480 colour, chase view and map)", rate(env.render)),
    ]  # fmt: skip
    env.close()
    print(f"{'figure':<58}{'value':>10}{'x DeepRacer':>13}")
    for name, value in figures:
        speedup = f"{value / DEEPRACER_STEPS_PER_SECOND:>12.0f}x" if "steps" in name else ""
        print(f"{name:<58}{value:>10,.0f}{speedup:>13}")


if __name__ == "__main__":
    main()
