"""Simulator speed and the car's grip: `python -m bench.bench_simulator [--no-grip]` (or `make
bench`).

Speed, one process, one core: environment steps per second with the camera on (the time in
``env.step`` as the centre-line driver drives, the default reward function, every status and
param computed; the driver's own planning is not counted), what the car's dynamics
cost, camera frames per second, and spectator frames per second. DeepRacer's Gazebo simulation
runs at 15 steps per second.

Grip, for each of Pitlane's own built-in tracks (its first direction; bench_tracks laps
DeepRacer's): the highest constant speed, in steps of 0.1 m/s, at which the scripted centre-line
driver laps cleanly (no reset), and its lap time; the fastest clean lap of the braking driver (a
speed profile from the track's curvature, planned on a share of the car's grip from 0.5 to 1.0 in
steps of 0.025, top speed 4 m/s), and the share that gave it.
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium

import simulator
from simulator import tracks
from simulator.car import Car
from simulator.config import CONTROL_HZ
from simulator.controller import BrakingDriver, CentreLineDriver

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
    """Environment steps per second: the time in ``env.step`` (and the resets it calls for) alone,
    not the driver's, which plans each command on a model of the steering (a policy's forward
    pass stands there in training, and is measured by bench_sandbox)."""
    env = gymnasium.make(simulator.ENV_ID, track="rookie-loop", **settings)
    env.reset(seed=0)
    driver = CentreLineDriver(env.unwrapped, speed=1.0)
    count, spent = -50, 0.0  # the first 50 steps warm up
    while spent < SECONDS:
        action = driver.act()
        started = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
        if count >= 0:
            spent += time.perf_counter() - started
        count += 1
    env.close()
    return count / spent


def pybullet_vehicle():
    """One control step of the alternative to our car: PyBullet's own rigid-body racecar
    (pybullet_data's racecar.urdf: wheels and steering on joints, motors on them) on a plane, at
    the 240 Hz its contact solver needs, 16 steps per 1/15 s."""
    import pybullet
    import pybullet_data
    from pybullet_utils.bullet_client import BulletClient

    client = BulletClient(connection_mode=pybullet.DIRECT)
    client.setAdditionalSearchPath(pybullet_data.getDataPath())
    client.setGravity(0, 0, -9.81)
    client.setTimeStep(1 / 240)
    client.loadURDF("plane.urdf")
    body = client.loadURDF("racecar/racecar.urdf", [0, 0, 0.05])
    for wheel in (2, 3, 5, 7):
        client.setJointMotorControl2(
            body, wheel, pybullet.VELOCITY_CONTROL, targetVelocity=30, force=10
        )
    for hinge in (4, 6):
        client.setJointMotorControl2(body, hinge, pybullet.POSITION_CONTROL, targetPosition=0.2)

    def step() -> None:
        for _ in range(16):
            client.stepSimulation()

    return step


CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.1, "high": 4}}


def evaluation(track: str, driver, *, direction: str = "counterclockwise", laps: int = 1) -> dict:
    """The last step's info of an evaluation of ``laps`` laps of ``track`` driven by
    ``driver(env)``, ended at its first reset."""
    env = gymnasium.make(
        simulator.ENV_ID,
        track=track,
        direction=direction,
        mode="evaluation",
        laps=laps,
        action_space=CONTINUOUS,
    )
    env.reset(seed=0)
    chosen = driver(env.unwrapped)
    while True:
        _, _, terminated, truncated, info = env.step(chosen.act())
        if terminated or truncated or info["resets"]:
            break
    env.close()
    return info


def lap(track: str, driver) -> float | None:
    """[s] the lap time of ``driver(env)`` on ``track``, None unless the lap was clean."""
    info = evaluation(track, driver)
    clean = info["status"] == "lap_complete" and not info["resets"]
    return info["lap_times"][0] if clean else None


def best_constant(track: str) -> tuple[float | None, float | None]:
    """([m/s] the fastest constant speed the centre-line driver laps ``track`` clean at, in
    tenths, its lap [s]); (None, None) when none does."""
    for tenths in range(40, 4, -1):
        speed = tenths / 10
        if time_ := lap(track, lambda env, v=speed: CentreLineDriver(env, speed=v)):
            return speed, time_
    return None, None


GRIP_SHARES = [share / 40 for share in range(20, 41)]  # 0.5 to 1.0 in steps of 0.025


def braking_lap(track: str) -> tuple[float | None, float | None]:
    """([s] the braking driver's fastest clean lap of ``track``, the grip share that gave it),
    over ``GRIP_SHARES``; (None, None) when none lapped clean."""
    laps = [
        (time, share)
        for share in GRIP_SHARES
        if (time := lap(track, lambda env, g=share: BrakingDriver(env, grip=g)))
    ]
    return min(laps) if laps else (None, None)


def grip_table() -> None:
    print(
        f"\n{'track':<22}{'length':>8}{'best constant':>15}{'its lap':>9}"
        f"{'braking lap':>13}{'grip share':>12}{'at 4 m/s':>10}"
    )
    for name in tracks.names(origin="pitlane"):
        best = best_constant(name)
        fastest, share = braking_lap(name)
        at_four = "clean" if best[0] == 4.0 else "fails"
        print(
            f"{name:<22}{tracks.load(name).length:>7.1f}m"
            f"{best[0] or 0:>13.1f}/s{best[1] or 0:>8.2f}s"
            f"{fastest or 0:>12.2f}s{share or 0:>12.3f}{at_four:>10}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--no-grip", action="store_true", help="the speed figures only")
    arguments = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, as promised
    env = gymnasium.make(simulator.ENV_ID, track="rookie-loop", render_mode="rgb_array")
    env.reset(seed=0)
    car = env.unwrapped
    camera = car._cameras[0]
    dynamic = Car()  # a steady turn at 2 m/s
    figures = [
        ("environment steps/s, camera, time trial", environment_steps()),
        ("  environment steps/s, the same with domain randomisation",
         environment_steps(randomise=True)),
        ("environment steps/s, stereo + lidar, 3 bot cars",
         environment_steps(sensors=["STEREO_CAMERAS", "LIDAR"], race_type="HEAD_TO_BOT")),
        ("car dynamics steps/s (Car.step alone, 8 sub-steps)",
         rate(lambda: dynamic.step(2.0, 10.0, 1 / 15))),
        ("  PyBullet's racecar.urdf instead, 240 Hz physics", rate(pybullet_vehicle())),
        ("environment steps/s, camera, 3 boxes",
         environment_steps(race_type="OBJECT_AVOIDANCE")),
        ("camera frames/s (160 x 120 grayscale)",
         rate(lambda: camera.render(car.car.x, car.car.y, car.car.yaw))),
        ("spectator frames/s (640 x 480 colour, chase view and map)", rate(env.render)),
    ]  # fmt: skip
    env.close()
    print(f"{'figure':<58}{'value':>10}{'x DeepRacer':>13}")
    for name, value in figures:
        speedup = f"{value / CONTROL_HZ:>12.0f}x" if "steps" in name else ""
        print(f"{name:<58}{value:>10,.0f}{speedup:>13}")
    if not arguments.no_grip:
        grip_table()


if __name__ == "__main__":
    main()
