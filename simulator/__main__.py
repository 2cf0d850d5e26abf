"""Command line: ``python -m simulator demo --track NAME --out demo.mp4``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import gymnasium

import simulator
from simulator import tracks
from simulator.config import ConfigError
from simulator.controller import CentreLineDriver
from simulator.tracks import TrackError


def demo(track: str, direction: str, speed: float, out: Path) -> str:
    """Drive one lap with the scripted centre-line driver and write the spectator video."""
    env = gymnasium.make(
        simulator.ENV_ID,
        track=track,
        direction=direction,
        mode="evaluation",
        laps=1,
        render_mode="rgb_array",
        action_space={"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.1, "high": 4}},
    )
    car = env.unwrapped
    driver = CentreLineDriver(car, speed=speed)
    env.reset(seed=0)
    out.parent.mkdir(parents=True, exist_ok=True)
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 15, (640, 480))
    if not writer.isOpened():
        raise OSError(f"cannot write a video to {out}")
    try:
        spectator = car.spectator
        writer.write(spectator.render(car))
        info, done = {}, False
        while not done:
            _, _, terminated, truncated, info = env.step(driver.act())
            writer.write(spectator.render(car))
            done = terminated or truncated
    finally:
        writer.release()
        env.close()
    laps = info.get("lap_times") or []
    return (
        f"{car.track.display_name} ({direction}, {car.track.length:.2f} m): "
        + (f"lap in {laps[0]:.3f} s at {speed} m/s" if laps else f"stopped: {info.get('status')}")
        + f"; video in {out}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m simulator", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    drive = commands.add_parser("demo", help="drive a lap along the centre line and film it")
    drive.add_argument("--track", required=True, help=f"one of: {', '.join(tracks.names())}")
    drive.add_argument("--direction", default="counterclockwise",
                       choices=["counterclockwise", "clockwise"])  # fmt: skip
    drive.add_argument("--speed", type=float, default=1.5, help="[m/s] 0.1 to 4 (default 1.5)")
    drive.add_argument("--out", type=Path, default=Path("demo.mp4"), help="the MP4 to write")
    arguments = parser.parse_args(argv)
    if not 0.1 <= arguments.speed <= 4:
        parser.error("--speed is 0.1 to 4 m/s")
    try:
        print(demo(arguments.track, arguments.direction, arguments.speed, arguments.out))  # noqa: T201
    except (TrackError, ConfigError, OSError) as error:
        print(f"python -m simulator: {error}", file=sys.stderr)  # noqa: T201
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
