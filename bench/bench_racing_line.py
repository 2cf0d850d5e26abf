"""The racing line against the drivers that lap a track: `python -m bench.bench_racing_line`.

For each of Pitlane's own built-in tracks (``--all``: every built-in track; ``--directions``: in
each of its directions, else its first), the racing line's computed laps (``simulator.
racing_line``, the stored line), the laps a driver that follows it drives in the simulator
(``RacingLineDriver``, an evaluation of 2 laps: the first from a standing start, the second
flying) and how far each is from the computed one, then the braking driver's fastest clean lap
and the centre line's best constant speed with its lap (both from a standing start,
counterclockwise, as ``bench_simulator`` drives them). The line must lap clean within 3% of its
computed time, quicker or slower: the last line says on how many lines the driver left the
track, and the largest gap of the others either way.
"""

from __future__ import annotations

import argparse
import time

from bench.bench_simulator import best_constant, braking_lap, evaluation
from simulator import tracks
from simulator.controller import RacingLineDriver
from simulator.racing_line import line_for


def followed(name: str, direction: str, line) -> tuple[float, float] | None:
    """([s] the standing lap, the flying lap) of the line's driver; None unless both are clean."""
    info = evaluation(name, lambda env: RacingLineDriver(env, line), direction=direction, laps=2)
    if info["status"] != "lap_complete" or info["resets"]:
        return None
    standing, flying = info["lap_times"]
    return standing, flying


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--all", action="store_true", help="every built-in track")
    parser.add_argument("--directions", action="store_true", help="each of a track's directions")
    parser.add_argument("--drivers", action="store_true", help="the braking and constant drivers")
    options = parser.parse_args()
    names = tracks.names() if options.all else tracks.names(origin="pitlane")
    print(
        f"{'track':<26}{'direction':<18}{'line (standing)':>16}{'driven':>8}{'gap':>7}"
        f"{'line (flying)':>14}{'driven':>8}{'gap':>7}"
        + (f"{'braking':>9}{'constant':>10}{'its lap':>9}" if options.drivers else "")
    )
    worst, lines, left, started = 0.0, 0, 0, time.perf_counter()
    for name in names:
        directions = tracks.entry(name)["directions"]
        for direction in directions if options.directions else directions[:1]:
            line = line_for(tracks.load(name).with_direction(direction))
            driven = followed(name, direction, line)
            lines += 1
            row = f"{name:<26}{direction:<18}{line.standing_lap_time:>15.2f}s"
            if driven is None:
                row += f"{'off':>8}{'':>7}{line.lap_time:>13.2f}s{'off':>8}{'':>7}"
                left += 1
            else:
                gaps = [
                    (driven[0] / line.standing_lap_time - 1) * 100,
                    (driven[1] / line.lap_time - 1) * 100,
                ]
                worst = max(worst, *map(abs, gaps))
                row += f"{driven[0]:>7.2f}s{gaps[0]:>6.1f}%{line.lap_time:>13.2f}s"
                row += f"{driven[1]:>7.2f}s{gaps[1]:>6.1f}%"
            if options.drivers and direction == "counterclockwise":  # as they drive it
                braking, _ = braking_lap(name)
                speed, its_lap = best_constant(name)
                row += f"{braking or 0:>8.2f}s{speed or 0:>8.1f}/s{its_lap or 0:>8.2f}s"
            print(row, flush=True)
    elapsed = time.perf_counter() - started
    print(f"\noff on {left} of {lines} lines; the largest gap: {worst:.1f}% ({elapsed:.0f} s)")


if __name__ == "__main__":
    main()
