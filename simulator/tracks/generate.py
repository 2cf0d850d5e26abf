"""Generates the built-in tracks in ``data/``: ``python -m simulator.tracks.generate``.

Each track is drawn as a closed outline of control points (or a formula sampled into one), smoothed
into a Catmull-Rom spline, resampled at even spacing and scaled to its lap length; the borders are
offset half the track width to either side. Before writing a file the script checks what a racer
would notice: no border crosses itself or the other, no bend is tighter than the car can take, and
no two parts of the track come so close that their surfaces touch. A track is never edited by hand.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from simulator.texture import preview
from simulator.tracks import DATA_DIR, _catalog, load, validate_array

STANDARD_WIDTH = 1.066  # [m] DeepRacer's usual track: 42 inches between the borders
SPACING = 0.15  # [m] between waypoints
CLEARANCE = 0.35  # [m] of surroundings at least between two parts of a track
BOTH = ("counterclockwise", "clockwise")


def _polar(*harmonics: tuple[int, float, float], points: int = 72) -> Callable[[], np.ndarray]:
    """An outline r(θ) = 1 + Σ aₖ·cos(kθ + φₖ), counter-clockwise from the +x axis."""

    def outline() -> np.ndarray:
        theta = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
        radius = 1.0 + sum(a * np.cos(k * theta + phase) for k, a, phase in harmonics)
        return np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])

    return outline


def _stadium(straight: float, radius: float) -> Callable[[], np.ndarray]:
    """Two straights joined by half circles, counter-clockwise from the middle of the bottom."""

    def outline() -> np.ndarray:
        half = straight / 2
        bottom = [(x, -radius) for x in np.linspace(0, half, 4)]
        right = [
            (half + radius * np.sin(a), -radius * np.cos(a)) for a in np.linspace(0, np.pi, 9)[1:-1]
        ]
        top = [(x, radius) for x in np.linspace(half, -half, 7)]
        left = [
            (-half - radius * np.sin(a), radius * np.cos(a)) for a in np.linspace(0, np.pi, 9)[1:-1]
        ]
        back = [(x, -radius) for x in np.linspace(-half, 0, 4)[:-1]]
        return np.array(bottom + right + top + left + back, dtype=float)

    return outline


def _wavy_stadium(
    straight: float, radius: float, amplitude: float, period: float
) -> Callable[[], np.ndarray]:
    """A stadium whose straights both snake in the same S-curves, a lane's width apart."""

    def outline() -> np.ndarray:
        xs = np.linspace(0.0, straight, 33)
        wave = amplitude * np.sin(2 * np.pi * xs / period)
        bottom = np.column_stack([xs, wave - radius])
        top = np.column_stack([xs[::-1], wave[::-1] + radius])
        turn = np.linspace(-np.pi / 2, np.pi / 2, 13)[1:-1]
        right = np.column_stack([straight + radius * np.cos(turn), radius * np.sin(turn)])
        left = np.column_stack([-radius * np.cos(turn), -radius * np.sin(turn)])
        return np.vstack([bottom, right, top, left])

    return outline


def _points(*points: tuple[float, float]) -> Callable[[], np.ndarray]:
    return lambda: np.array(points, dtype=float)


@dataclass(frozen=True)
class TrackSpec:
    name: str
    display_name: str
    description: str
    difficulty: str
    length: float  # [m] of the centre line
    width: float  # [m] border to border
    outline: Callable[[], np.ndarray]
    directions: tuple[str, ...] = BOTH
    min_bend_radius: float = 0.8  # [m] of the centre line
    smoothing: float = 0.4  # [m] how far the corners of the outline are rounded off
    start_at: float = 0.0  # where the start line is, as a fraction of the outline's lap


SPECS = (
    TrackSpec(
        name="rookie-loop",
        display_name="Rookie Loop",
        description="A short, narrow beginner loop in the manner of re:Invent 2018: "
        "gentle bends and one lazy chicane.",
        difficulty="beginner",
        length=17.6,
        width=0.76,
        outline=_points(
            (0, 0),
            (3, 0),
            (5, 0.4),
            (6.2, 1.8),
            (5.8, 3.4),
            (4.4, 4.0),
            (3.3, 3.3),
            (2.1, 3.3),
            (1.0, 4.0),
            (-0.6, 3.6),
            (-1.2, 2.0),
            (-0.9, 0.6),
        ),
        min_bend_radius=0.6,
    ),
    TrackSpec(
        name="pitlane-oval",
        display_name="Pitlane Oval",
        description="Two long straights joined by wide bends: the place to learn speed.",
        difficulty="beginner",
        length=16.5,
        width=STANDARD_WIDTH,
        outline=_stadium(straight=4.0, radius=1.6),
    ),
    TrackSpec(
        name="kidney-bean",
        display_name="Kidney Bean",
        description="A lazy left, a long right-hand kink and a fast return straight.",
        difficulty="intermediate",
        length=19.0,
        width=STANDARD_WIDTH,
        outline=_polar((2, 0.18, 0.0), (3, 0.10, 0.6)),
        start_at=0.72,
    ),
    TrackSpec(
        name="s-bend",
        display_name="S-Bend Loop",
        description="Both sides of this loop snake in S-curves: rhythm and smooth steering pay.",
        difficulty="intermediate",
        length=26.0,
        width=STANDARD_WIDTH,
        outline=_wavy_stadium(straight=10.0, radius=1.6, amplitude=0.45, period=5.0),
    ),
    TrackSpec(
        name="speedway",
        display_name="Speedway",
        description="A wide tri-oval with long straights: carry speed through the banked bends.",
        difficulty="intermediate",
        length=34.0,
        width=1.5,
        outline=_polar((2, 0.32, 0.0), (3, 0.07, np.pi)),
        start_at=0.75,
        min_bend_radius=1.5,
    ),
    TrackSpec(
        name="clover-loop",
        display_name="Clover Loop",
        description="Four lobes and four tight inward kinks that punish a late turn-in.",
        difficulty="advanced",
        length=24.0,
        width=STANDARD_WIDTH,
        outline=_polar((4, 0.12, 0.0), (1, 0.06, 1.1)),
    ),
    TrackSpec(
        name="hairpin-alley",
        display_name="Hairpin Alley",
        description="A technical track: two hairpins that fold the lap back on itself, "
        "and short straights between them.",
        difficulty="advanced",
        length=48.0,
        width=STANDARD_WIDTH,
        outline=_points(
            (0, 0),
            (2.2, 0),
            (3.0, 0.8),
            (3.1, 2.6),
            (3.9, 3.5),
            (4.9, 3.5),
            (5.6, 2.6),
            (5.7, 0.8),
            (6.5, 0),
            (10.5, 0),
            (11.6, 0.9),
            (11.6, 6.4),
            (10.8, 7.2),
            (10, 7.0),
            (9.5, 6.2),
            (9.4, 4.4),
            (8.6, 3.6),
            (7.6, 3.8),
            (7.1, 4.8),
            (7.0, 6.4),
            (6.2, 7.2),
            (0, 7.2),
            (-1.0, 6.3),
            (-1.0, 0.9),
        ),
        min_bend_radius=0.7,
        smoothing=0.7,
    ),
    TrackSpec(
        name="championship-circuit",
        display_name="Championship Circuit",
        description="A long championship-style circuit: a main straight, a hairpin, a chicane "
        "and fast sweepers. Only counter-clockwise, as raced.",
        difficulty="expert",
        length=60.0,
        width=STANDARD_WIDTH,
        outline=_points(
            (0.6, 0),
            (10, 0),
            (13, 0.5),
            (14.6, 2.2),
            (14.2, 4.2),
            (12.4, 4.8),
            (10.8, 4.3),
            (9.6, 4.5),
            (9.0, 5.6),
            (9.4, 6.6),
            (11.6, 7.2),
            (13.8, 8.2),
            (13.6, 10.2),
            (10, 10.8),
            (6.2, 10.5),
            (4.6, 10.0),
            (3.9, 8.8),
            (4.6, 7.4),
            (4.4, 5.6),
            (2.6, 5.4),
            (0.8, 6.6),
            (-1.4, 6.2),
            (-2.0, 3.6),
            (-1.8, 1.4),
            (-0.9, 0.25),
        ),
        directions=("counterclockwise",),
        min_bend_radius=0.7,
    ),
)


def catmull_rom(control: np.ndarray, samples: int = 24) -> np.ndarray:
    """A closed, smooth curve through ``control`` points (uniform Catmull-Rom), densely sampled."""
    p0, p1, p2, p3 = (np.roll(control, -k, axis=0) for k in (-1, 0, 1, 2))
    t = np.linspace(0.0, 1.0, samples, endpoint=False)[:, None, None]
    curve = 0.5 * (
        2 * p1
        + (-p0 + p2) * t
        + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2
        + (-p0 + 3 * p1 - 3 * p2 + p3) * t**3
    )
    return curve.transpose(1, 0, 2).reshape(-1, 2)


def smooth(line: np.ndarray, length: float, radius: float) -> np.ndarray:
    """The closed, evenly spaced line with its corners rounded: a circular Gaussian filter of
    ``radius`` metres, then resampled to ``length`` again."""
    ring = line[:-1]
    sigma = radius / SPACING
    offsets = np.arange(-int(4 * sigma), int(4 * sigma) + 1)
    weights = np.exp(-0.5 * (offsets / sigma) ** 2)
    weights /= weights.sum()
    smoothed = sum(w * np.roll(ring, -k, axis=0) for k, w in zip(offsets, weights, strict=True))
    return resample(smoothed, length)


def resample(curve: np.ndarray, length: float, spacing: float = SPACING) -> np.ndarray:
    """The closed curve scaled to ``length`` and resampled every ``spacing`` metres, closed."""
    closed = np.vstack([curve, curve[:1]])
    steps = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    closed = closed * (length / steps.sum())
    along = np.concatenate([[0.0], np.cumsum(steps * (length / steps.sum()))])
    count = round(length / spacing)
    wanted = np.linspace(0.0, length, count, endpoint=False)
    line = np.column_stack([np.interp(wanted, along, closed[:, k]) for k in (0, 1)])
    if _signed_area(line) < 0:  # built tracks run counter-clockwise
        line = line[::-1]
    return np.vstack([line, line[:1]])


def borders(centre: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Inner (left, for counter-clockwise travel) and outer borders, offset along the normals."""
    ring = centre[:-1]
    tangent = np.roll(ring, -1, axis=0) - np.roll(ring, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    inner, outer = ring + left * width / 2, ring - left * width / 2
    return np.vstack([inner, inner[:1]]), np.vstack([outer, outer[:1]])


def bend_radii(centre: np.ndarray) -> np.ndarray:
    """The radius of the circle through each three consecutive centre points [m]."""
    a, b, c = np.roll(centre[:-1], 1, axis=0), centre[:-1], np.roll(centre[:-1], -1, axis=0)
    ab, bc, ca = (np.linalg.norm(u - v, axis=1) for u, v in ((a, b), (b, c), (c, a)))
    cross = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    with np.errstate(divide="ignore"):
        return ab * bc * ca / (2.0 * cross)


def closest_approach(centre: np.ndarray, width: float) -> float:
    """The smallest distance between two centre points that are far apart along the track [m]."""
    ring = centre[:-1]
    along = np.arange(len(ring)) * SPACING
    gap = np.abs(along[:, None] - along[None, :])
    apart = np.minimum(gap, along[-1] + SPACING - gap) > 2.5 * width
    distance = np.linalg.norm(ring[:, None, :] - ring[None, :, :], axis=2)
    return float(distance[apart].min()) if apart.any() else np.inf


def build(spec: TrackSpec) -> np.ndarray:
    centre = smooth(resample(catmull_rom(spec.outline()), spec.length), spec.length, spec.smoothing)
    ring = np.roll(centre[:-1], -round(spec.start_at * (len(centre) - 1)), axis=0)
    centre = np.vstack([ring, ring[:1]])
    tightest = float(bend_radii(centre).min())
    if tightest < spec.min_bend_radius:
        raise ValueError(f"{spec.name}: its tightest bend has a {tightest:.2f} m radius")
    approach = closest_approach(centre, spec.width)
    if approach < spec.width + CLEARANCE:
        raise ValueError(f"{spec.name}: two parts of the track come within {approach:.2f} m")
    inner, outer = borders(centre, spec.width)
    array = np.hstack([centre, inner, outer]).astype(np.float64)
    validate_array(array)
    return array


def _signed_area(ring: np.ndarray) -> float:
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def main() -> None:
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    catalog = []
    for spec in SPECS:
        np.save(DATA_DIR / f"{spec.name}.npy", build(spec))
        catalog.append(
            {
                "name": spec.name,
                "display_name": spec.display_name,
                "description": spec.description,
                "difficulty": spec.difficulty,
                "directions": list(spec.directions),
            }
        )
    with open(DATA_DIR / "catalog.json", "w") as file:
        json.dump(catalog, file, indent=2)
        file.write("\n")
    _catalog.cache_clear()
    for spec in SPECS:
        cv2.imwrite(
            str(DATA_DIR / f"{spec.name}.png"),
            preview(load(spec.name)),
            [cv2.IMWRITE_PNG_COMPRESSION, 9],
        )


if __name__ == "__main__":
    main()
