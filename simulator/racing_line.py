"""The racing line: the fastest way round a track for our car as the simulator drives it.

Two stages (decision 0014). First the least-curvature line: offsets from the centre line, every
``SPACING`` metres, that make the sum of the squared turns least, each offset kept within the
borders less half the car's width and the racer's ``margin`` (a convex quadratic within bounds);
the quickest of its blends with the shortest way round. Then that line refined for time: a
periodic cubic spline of offsets every ``KNOT_SPACING`` metres added to it, chosen by L-BFGS-B to
make the lap time of its speed profile least, every offset clipped to the same bounds.

The speed profile is the car's (``Limits.of``): at each point the highest speed whose
centripetal acceleration the tyres' grip holds, at most the car's top speed, then held to what
the car can gain accelerating out of each bend and must shed braking into the next, round the
loop. The simulator's tyres grip with Coulomb friction clipped along and across each axle
separately (``simulator.car``, Gazebo's pyramid), so cornering and braking each have the whole
of mu * g; ``GRIP`` is the share of it the line asks for in the bends, and the rest is what the
tracking driver (``simulator.controller.RacingLineDriver``) corrects with. The built-in tracks'
lines are stored (``LINES_DIR``, ``python -m simulator.racing_line``), each with the key of what
it was computed from.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import optimize, sparse
from scipy.interpolate import CubicSpline

from simulator import tracks
from simulator.car import GRAVITY, CarSpec
from simulator.tracks import DATA_DIR, Track

LINES_DIR = DATA_DIR / "lines"  # the built-in tracks' lines: ``python -m simulator.racing_line``
METHOD = 4  # raised when the method changes (the constants below are in the key too)

SPACING = 0.1  # [m] between the line's points
KNOT_SPACING = 0.5  # [m] between the knots of the time refinement's offsets
GRIP = 0.8  # of mu * g, asked for in the bends (the driver needs the rest to correct)
MIN_CURVATURE = 1e-4  # [1/m] below which a stretch is straight
EPS = 1e-5  # [m] a knot's step in the refinement's finite differences
PENALTY = 100.0  # [s per m², per (1/m)²] of the line's kinks and too sharp bends
STEERING = 0.7  # of the sharpest bend the steering turns, the most the line asks for
RESTARTS = 4  # of the refinement, while each gains a tenth of a millisecond or more


@dataclass(frozen=True)
class Limits:
    """What the car can do, for the speed profile."""

    top_speed: float  # [m/s]
    cornering: float  # [m/s²] the centripetal acceleration the line asks for at most
    accelerating: float  # [m/s²]
    braking: float  # [m/s²]
    tightest: float = math.inf  # [1/m] the sharpest bend the line may have

    @classmethod
    def of(cls, spec: CarSpec, grip: float = GRIP) -> Limits:
        """The simulator's car: its top speed (the wheels' velocity limit at the largest speed
        the action may ask) and mu * g along and (a share ``grip`` of it) across."""
        friction = spec.friction * GRAVITY
        # A share of the sharpest the steering turns (30°: 1 / 0.28 m), as of the grip.
        tightest = STEERING * math.tan(math.radians(spec.max_steering)) / spec.wheelbase
        return cls(spec.wheel_target(spec.max_speed), grip * friction, friction, friction, tightest)


@dataclass(frozen=True)
class RacingLine:
    """A closed line of ``points`` (N, 2) [m] from the start line, not repeating the first, the
    speed [m/s] the car carries at each on a flying lap, and the laps it gives [s]: a flying
    lap's, and the first lap's from a standing start, as a race's first lap begins."""

    points: np.ndarray
    speeds: np.ndarray
    lap_time: float
    standing_lap_time: float
    margin: float

    def as_track(self, track: Track) -> Track:
        """The line as a track of its own (its centre, borders 0.3 m either side), for the
        geometry a driver that follows it reads: projection, heading, curvature."""
        closed = np.vstack([self.points, self.points[:1]])
        tangent = np.gradient(closed, axis=0)
        tangent /= np.hypot(tangent[:, 0], tangent[:, 1])[:, None]
        left = np.column_stack([-tangent[:, 1], tangent[:, 0]]) * 0.3
        return Track(
            name=f"{track.name}-racing-line",
            display_name=f"{track.display_name}'s racing line",
            centre=closed,
            inner=closed + left,
            outer=closed - left,
            direction=track.direction,
        )

    @property
    def curvature(self) -> np.ndarray:
        """[1/m] at each point, positive where the line turns left."""
        return _curvature(self.points)[0]


def racing_line(
    track: Track, spec: CarSpec | None = None, margin: float = 0.0, grip: float = GRIP
) -> RacingLine:
    """The fastest line round ``track`` (in its direction) for the car of ``spec``, ``margin``
    metres inside the borders beyond half the car's width."""
    spec = spec or CarSpec()
    limits = Limits.of(spec, grip)
    centre, normals, low, high = _corridor(track, spec.width / 2 + margin)
    offsets = _quickest(
        centre, normals, low, high, _blended(centre, normals, low, high, limits), limits
    )
    points = centre + offsets[:, None] * normals
    speeds, lap_time = speed_profile(points, limits)
    # From rest at the start line: v² = 2 a s until the flying lap's speed is reached.
    steps = _curvature(points)[1]
    along = np.concatenate([[0.0], np.cumsum(steps)])[:-1]
    standing = from_rest(speeds, along, limits.accelerating)
    arriving = np.append(standing[1:], speeds[0])  # the lap ends at the flying lap's speed
    standing_time = float((steps / ((standing + arriving) / 2)).sum())
    return RacingLine(points, speeds, lap_time, standing_time, margin)


def from_rest(speeds: np.ndarray, along: np.ndarray, accelerating: float) -> np.ndarray:
    """[m/s] ``speeds`` as a car that starts from rest at ``along`` 0 [m] reaches them, gaining
    at most ``accelerating`` [m/s²]: v² = 2 a s until each is reached."""
    return np.minimum(speeds, np.sqrt(2 * accelerating * along))


def speed_profile(points: np.ndarray, limits: Limits) -> tuple[np.ndarray, float]:
    """[m/s] the speed at each of the closed line's ``points``, and the lap time [s]."""
    curvature, steps = _curvature(points)
    cap = np.minimum(
        np.sqrt(limits.cornering / np.maximum(np.abs(curvature), MIN_CURVATURE)),
        limits.top_speed,
    )
    # Round the loop three times so that each limit carries over the start line; the middle
    # lap's. Accelerating from a point k: v(s)² <= cap_k² + 2 a (s - s_k), all k before s.
    n = len(points)
    travelled = np.concatenate([[0.0], np.cumsum(np.tile(steps, 3))])[:-1]
    capped = np.tile(cap, 3) ** 2
    gained = np.minimum.accumulate(capped - 2 * limits.accelerating * travelled)
    forward = gained + 2 * limits.accelerating * travelled
    to_go = travelled[-1] - travelled
    shed = np.minimum.accumulate((capped - 2 * limits.braking * to_go)[::-1])[::-1]
    backward = shed + 2 * limits.braking * to_go
    speeds = np.sqrt(np.minimum(forward, backward)[n : 2 * n])
    mean = (speeds + np.roll(speeds, -1)) / 2
    return speeds, float((steps / mean).sum())


def _corridor(track: Track, inset: float):
    """The centre line every ``SPACING`` metres, its left normals, and the offsets (left
    positive) between which the car's middle keeps ``inset`` metres inside the borders. The
    centre here is a periodic cubic spline through the waypoints: a route file's polyline turns
    only at its points, which would read as a kink every half metre."""
    steps = np.hypot(*np.diff(track.centre, axis=0).T)
    along = np.concatenate([[0.0], np.cumsum(steps)])
    spline = CubicSpline(along, track.centre, bc_type="periodic")
    count = max(round(along[-1] / SPACING), 20)
    distances = np.arange(count) * (along[-1] / count)
    centre = spline(distances)
    tangent = spline(distances, 1)
    tangent /= np.hypot(tangent[:, 0], tangent[:, 1])[:, None]
    normals = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    where = track.project_points(centre)
    left, right = track.half_widths
    high = np.interp(where.distance, track.along, left) - inset
    low = -(np.interp(where.distance, track.along, right) - inset)
    middle = (low + high) / 2  # a stretch narrower than the car: its middle, no room either way
    return centre, normals, np.minimum(low, middle), np.maximum(high, middle)


def _least(centre, normals, low, high, order: int) -> np.ndarray:
    """The offsets whose line has the least sum of squared differences of ``order`` (2: the
    least curvature; 1: the shortest way round): a convex quadratic in the offsets within their
    bounds, whose sparse matrix gives L-BFGS-B its exact gradient (a dense bounded least squares
    took 27 s on an 89 m track, this 1 s)."""
    n = len(centre)
    ahead = sparse.csr_matrix((np.ones(n), (np.arange(n), (np.arange(n) + 1) % n)), shape=(n, n))
    identity = sparse.identity(n, format="csr")
    # p[i+1] - p[i], or p[i-1] - 2 p[i] + p[i+1]
    differences = ahead - identity if order == 1 else ahead + ahead.T - 2 * identity
    matrix = sparse.vstack([differences @ sparse.diags(normals[:, axis]) for axis in (0, 1)])
    target = -np.concatenate([differences @ centre[:, 0], differences @ centre[:, 1]])
    square, linear = (matrix.T @ matrix).tocsr(), matrix.T @ target

    def objective(offsets: np.ndarray) -> tuple[float, np.ndarray]:
        pulled = square @ offsets
        return offsets @ pulled - 2 * linear @ offsets, 2 * (pulled - linear)

    found = optimize.minimize(
        objective,
        np.clip(np.zeros(n), low, high),
        jac=True,
        method="L-BFGS-B",
        bounds=optimize.Bounds(low, high),
        options={"maxiter": 50_000, "ftol": 1e-15, "gtol": 1e-12},
    )
    return found.x


def _blended(centre, normals, low, high, limits: Limits) -> np.ndarray:
    """The quickest of the lines between the least-curvature and the shortest (each offset a
    share of the way from one to the other, so every one is within the bounds)."""
    curving, shortest = (_least(centre, normals, low, high, order) for order in (2, 1))
    blends = [curving + share * (shortest - curving) for share in np.linspace(0.0, 1.0, 11)]
    laps = [_cost(centre, normals, blend, blend, limits) for blend in blends]
    return blends[int(np.argmin(laps))]


def _cost(centre, normals, wanted, offsets, limits: Limits) -> float:
    """[s] the lap of the line of ``offsets``, and what would make it undrivable: how far the
    offsets ``wanted`` were cut to the bounds (a cut is a kink), bends tighter than the
    steering turns."""
    points = centre + offsets[:, None] * normals
    tight = np.maximum(np.abs(_curvature(points)[0]) - limits.tightest, 0.0)
    cut = wanted - offsets
    return speed_profile(points, limits)[1] + PENALTY * ((cut**2).sum() + (tight**2).sum())


def _quickest(centre, normals, low, high, start, limits: Limits) -> np.ndarray:
    """``start`` refined for the lap time: a periodic spline of offsets added, clipped."""
    n = len(centre)
    knots = max(round(n * SPACING / KNOT_SPACING), 8)
    at = np.arange(n) / n
    where = np.linspace(0.0, 1.0, knots + 1)
    basis = np.empty((n, knots))
    for k in range(knots):
        values = np.zeros(knots + 1)
        values[k] = 1.0
        values[-1] = values[0]
        basis[:, k] = CubicSpline(where, values, bc_type="periodic")(at)

    def lap(change: np.ndarray) -> float:
        wanted = start + basis @ change
        return _cost(centre, normals, wanted, np.clip(wanted, low, high), limits)

    change, best = np.zeros(knots), lap(np.zeros(knots))
    for _ in range(RESTARTS):  # the lap time is rough: L-BFGS-B stops short, and goes on anew
        found = optimize.minimize(
            lap, change, method="L-BFGS-B", options={"maxiter": 1000, "maxfun": 50_000, "eps": EPS}
        )
        if found.fun > best - 1e-4:
            break
        change, best = found.x, found.fun
    return np.clip(start + basis @ change, low, high)


def _curvature(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[1/m] the closed line's turn at each point over its two half-steps, and [m] each step
    to the next point."""
    ahead = np.roll(points, -1, axis=0) - points
    steps = np.hypot(ahead[:, 0], ahead[:, 1])
    heading = np.arctan2(ahead[:, 1], ahead[:, 0])
    turn = np.angle(np.exp(1j * (heading - np.roll(heading, 1))))
    return turn / ((steps + np.roll(steps, 1)) / 2), steps


# Stored lines


def line_key(track: Track, spec: CarSpec, margin: float) -> str:
    """What a line is computed from: the track's geometry in its direction, the car, the margin
    and the method. A stored line whose key differs is stale."""
    digest = hashlib.sha256()
    for array in (track.centre, track.inner, track.outer):
        digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    method = (METHOD, SPACING, KNOT_SPACING, GRIP, MIN_CURVATURE, EPS, PENALTY, STEERING, RESTARTS)
    method += (round(margin, 6),)
    digest.update(repr((method, spec)).encode())
    return digest.hexdigest()


def stored_line(track: Track, spec: CarSpec | None = None) -> RacingLine | None:
    """The built-in ``track``'s stored line (no margin) in its direction; None if none is
    stored, or it was computed from another track, car or method."""
    path = LINES_DIR / f"{track.name}.npz"
    if not path.is_file():
        return None
    with np.load(path) as data:
        name = track.direction
        if f"{name}_key" not in data or str(data[f"{name}_key"]) != line_key(
            track, spec or CarSpec(), 0.0
        ):
            return None
        laps = data[f"{name}_laps"]
        return RacingLine(
            data[f"{name}_points"].astype(np.float64),
            data[f"{name}_speeds"].astype(np.float64),
            float(laps[0]),
            float(laps[1]),
            0.0,
        )


def line_for(track: Track, spec: CarSpec | None = None, margin: float = 0.0) -> RacingLine:
    """``track``'s racing line: the stored one where it is current, else computed (1 to 10 s
    of CPU, the longest tracks the most: off any request's thread)."""
    line = stored_line(track, spec) if margin == 0.0 else None
    return line or racing_line(track, spec, margin)


def _store(name: str) -> list[str]:
    """Compute and store built-in ``name``'s line in each of its directions; a line a report."""
    arrays, report = {}, []
    for direction in tracks.entry(name)["directions"]:
        track = tracks.load(name).with_direction(direction)
        line = racing_line(track)
        arrays[f"{direction}_points"] = line.points.astype(np.float32)
        arrays[f"{direction}_speeds"] = line.speeds.astype(np.float32)
        arrays[f"{direction}_laps"] = np.array([line.lap_time, line.standing_lap_time])
        arrays[f"{direction}_key"] = np.array(line_key(track, CarSpec(), 0.0))
        report.append(
            f"{name:<32}{direction:<18}{line.lap_time:>8.2f}s{line.standing_lap_time:>10.2f}s"
        )
    LINES_DIR.mkdir(exist_ok=True)
    np.savez_compressed(LINES_DIR / f"{name}.npz", **arrays)
    return report


def main() -> None:
    parser = argparse.ArgumentParser(description="Store the built-in tracks' racing lines.")
    parser.add_argument("names", nargs="*", help="tracks (default: every built-in one)")
    options = parser.parse_args()
    for name in options.names:
        try:
            tracks.entry(name)
        except tracks.TrackError as error:  # before any work
            parser.error(str(error))
    print(f"{'track':<32}{'direction':<18}{'flying':>9}{'standing':>11}")  # noqa: T201
    # A process a core, each numerical library on one thread in it (their pools would contend).
    os.environ.update({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"})
    with ProcessPoolExecutor(mp_context=multiprocessing.get_context("spawn")) as pool:
        for report in pool.map(_store, options.names or tracks.names()):
            print("\n".join(report), flush=True)  # noqa: T201


if __name__ == "__main__":
    main()
