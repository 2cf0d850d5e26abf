"""DeepRacer's catalogue, every route file: `python -m bench.bench_tracks [--speed 1.5]`.

Each of the route files under simulator/tracks/data/deepracer/routes (simapp's bundle/routes,
01f5f01, less its open Straight_track) is loaded by the simulator's loader exactly as shipped and
driven for one lap in the direction its waypoints run by the scripted centre-line driver at a
constant speed, in evaluation mode (an off-track resets the car and counts). Printed per file: its
WORLD_NAME, the track it belongs to, its direction, waypoints, length, median and narrowest
width, and the lap time (the simulated time, so penalties would show); then the count, the
shortest and longest, narrowest and widest, and how many lapped clean. The suite laps six of them
(tests/simulator/test_env.py DEEPRACER_LAPS).
"""

from __future__ import annotations

import argparse
import time

import gymnasium

import simulator
from simulator import tracks
from simulator.controller import CentreLineDriver
from simulator.tracks import DEEPRACER_DIR

CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.1, "high": 4}}


def lap(path: str, direction: str, speed: float) -> dict:
    """One evaluation lap of the route file at ``path``: its status, lap time and resets."""
    env = gymnasium.make(
        simulator.ENV_ID,
        track=path,
        direction=direction,
        mode="evaluation",
        laps=1,
        action_space=CONTINUOUS,
    )
    env.reset(seed=0)
    driver = CentreLineDriver(env.unwrapped, speed=speed)
    while True:
        _, _, terminated, truncated, info = env.step(driver.act())
        if terminated or truncated:
            break
    env.close()
    return {
        "status": info["status"],
        "time": (info["lap_times"] or [None])[0],
        "resets": info["resets"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speed", type=float, default=1.5, help="[m/s] the driver's speed")
    speed = parser.parse_args().speed
    rows, started = [], time.perf_counter()
    print(
        f"{'WORLD_NAME':<28}{'track':<38}{'direction':<18}{'points':>7}{'length':>9}"
        f"{'width':>8}{'narrowest':>10}{'lap':>9}  result"
    )
    for name in tracks.names(origin="deepracer"):
        for world_name, direction in tracks.entry(name)["world_names"].items():
            path = DEEPRACER_DIR / "routes" / f"{world_name}.npy"
            track = tracks.load(path)
            result = lap(str(path), direction, speed)
            clean = result["status"] == "lap_complete" and not result["resets"]
            rows.append((world_name, track, clean, result["time"]))
            shown = f"{result['time']:.2f}s" if result["time"] else "-"
            said = "clean" if clean else result["status"]
            print(
                f"{world_name:<28}{tracks.entry(name)['display_name'][:37]:<38}{direction:<18}"
                f"{len(track.centre) - 1:>7}{track.length:>8.2f}m{track.width:>7.3f}m"
                f"{track.widths.min():>9.3f}m{shown:>9}  {said}, {result['resets']} resets"
            )
    lengths = sorted((t.length, w) for w, t, _, _ in rows)
    widths = sorted((t.width, w) for w, t, _, _ in rows)
    clean = [row for row in rows if row[2]]
    print(
        f"\n{len(rows)} route files of {len(tracks.names(origin='deepracer'))} tracks; "
        f"length {lengths[0][0]:.2f} m ({lengths[0][1]}) to {lengths[-1][0]:.2f} m "
        f"({lengths[-1][1]}); median width {widths[0][0]:.3f} m ({widths[0][1]}) to "
        f"{widths[-1][0]:.3f} m ({widths[-1][1]})"
    )
    print(
        f"{len(clean)} of {len(rows)} lapped clean at {speed} m/s, in "
        f"{min(r[3] for r in clean):.2f} s to {max(r[3] for r in clean):.2f} s; "
        f"the bench took {time.perf_counter() - started:.0f} s"
    )


if __name__ == "__main__":
    main()
