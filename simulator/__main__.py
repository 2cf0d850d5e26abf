"""Command line: ``python -m simulator demo --track NAME [--speed M/S] [--braking] --out FILE``.

A scripted driver laps the track along its centre line and films it. At a constant speed too high
for a track's corners the car slides, and leaves the track (``--track hairpin-alley --speed 3``);
with ``--braking`` the driver brakes for each corner as the car's grip asks, and laps faster."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import gymnasium

import simulator
from simulator import tracks
from simulator.config import ConfigError
from simulator.controller import BrakingDriver, CentreLineDriver
from simulator.tracks import TrackError


def demo(track: str, direction: str, speed: float, out: Path, braking: bool = False) -> str:
    """Drive one lap with the scripted centre-line driver and write the spectator video; what
    happened, in a line."""
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
    env.reset(seed=0)
    driver = (BrakingDriver if braking else CentreLineDriver)(car, speed=speed)
    slid = 0
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
            slid += car.car.sliding
            writer.write(spectator.render(car))
            done = terminated or truncated
    finally:
        writer.release()
        env.close()
    laps = info.get("lap_times") or []
    how = f"braking for corners, up to {speed} m/s" if braking else f"at {speed} m/s"
    happened = f"lap in {laps[0]:.3f} s {how}" if laps else f"stopped: {info.get('status')}"
    if slid:
        happened += f"; slid for {slid / car.config['control_hz']:.1f} s"
    if info.get("resets"):
        happened += f", left the track {info['resets']} time{'s' if info['resets'] > 1 else ''}"
    return (
        f"{car.track.display_name} ({direction}, {car.track.length:.2f} m): {happened}; "
        f"video in {out}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m simulator", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    drive = commands.add_parser("demo", help="drive a lap along the centre line and film it")
    drive.add_argument(
        "--track",
        required=True,
        help=f"one of: {', '.join(tracks.names(origin='pitlane'))}, or one of DeepRacer's by its "
        "WORLD_NAME (reInvent2019_track, 2022_april_open_cw, ...)",
    )
    drive.add_argument(
        "--direction", default="counterclockwise", choices=["counterclockwise", "clockwise"]
    )
    drive.add_argument(
        "--speed",
        type=float,
        default=1.5,
        help="[m/s] 0.1 to 4 (default 1.5); with --braking, the top speed",
    )
    drive.add_argument("--braking", action="store_true", help="brake for corners, as the grip asks")
    drive.add_argument("--out", type=Path, default=Path("demo.mp4"), help="the MP4 to write")
    arguments = parser.parse_args(argv)
    if not 0.1 <= arguments.speed <= 4:
        parser.error("--speed is 0.1 to 4 m/s")
    try:
        line = demo(
            arguments.track, arguments.direction, arguments.speed, arguments.out, arguments.braking
        )
        print(line)  # noqa: T201
    except (TrackError, ConfigError, OSError) as error:
        print(f"python -m simulator: {error}", file=sys.stderr)  # noqa: T201
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
