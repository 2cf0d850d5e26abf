"""Generates the built-in tracks in ``data/``: ``python -m simulator.tracks.generate``.

Each track is a smooth closed centre line, given as a polar curve r(θ) = R·(1 + Σ aₖ·cos(kθ + φₖ)),
scaled to a chosen lap length, with borders offset half the track width to either side. The
script checks what a racer would notice (no border crosses itself; no bend tighter than the car can
take) before it writes a file, so a track is never edited by hand.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass

import numpy as np

from simulator.tracks import DATA_DIR, validate_array

TRACK_WIDTH = 1.066  # [m] DeepRacer's standard: 42 inches between the borders' outer edges
POINTS = 160  # centre-line points per lap, about DeepRacer's density on a 20 m track
MIN_BEND_RADIUS = 0.75  # [m] tighter than this and the car cannot follow at full lock


@dataclass(frozen=True)
class TrackSpec:
    name: str
    display_name: str
    description: str
    difficulty: str
    length: float  # [m] centre-line length
    harmonics: tuple[tuple[int, float, float], ...]  # (k, aₖ, φₖ [rad])
    directions: tuple[str, ...] = ("counterclockwise", "clockwise")


SPECS = (
    TrackSpec(
        name="pitlane-oval",
        display_name="Pitlane Oval",
        description="Two long straights joined by wide bends: the place to learn speed.",
        difficulty="beginner",
        length=16.5,
        harmonics=((2, 0.22, 0.0),),
    ),
    TrackSpec(
        name="kidney-bean",
        display_name="Kidney Bean",
        description="A lazy left, a long right-hand kink and a fast return straight.",
        difficulty="intermediate",
        length=19.0,
        harmonics=((2, 0.18, 0.0), (3, 0.10, 0.6)),
    ),
    TrackSpec(
        name="clover-loop",
        display_name="Clover Loop",
        description="Four lobes and four tight inward kinks that punish a late turn-in.",
        difficulty="advanced",
        length=24.0,
        harmonics=((4, 0.12, 0.0), (1, 0.06, 1.1)),
    ),
)


def centre_line(spec: TrackSpec, points: int = POINTS) -> np.ndarray:
    """The closed centre line, counter-clockwise, starting on the +x axis, scaled to the length."""
    theta = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    radius = np.ones_like(theta)
    for k, amplitude, phase in spec.harmonics:
        radius += amplitude * np.cos(k * theta + phase)
    line = np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])
    closed = np.vstack([line, line[:1]])
    length = np.linalg.norm(np.diff(closed, axis=0), axis=1).sum()
    return closed * (spec.length / length)


def borders(centre: np.ndarray, width: float) -> tuple[np.ndarray, np.ndarray]:
    """Inner (left, for counter-clockwise travel) and outer borders, offset along the normals."""
    ring = centre[:-1]
    tangent = np.roll(ring, -1, axis=0) - np.roll(ring, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    inner = ring + left * width / 2
    outer = ring - left * width / 2
    return np.vstack([inner, inner[:1]]), np.vstack([outer, outer[:1]])


def min_bend_radius(centre: np.ndarray) -> float:
    """The smallest radius of the circle through any three consecutive centre points [m]."""
    a, b, c = np.roll(centre[:-1], 1, axis=0), centre[:-1], np.roll(centre[:-1], -1, axis=0)
    ab, bc, ca = (np.linalg.norm(u - v, axis=1) for u, v in ((a, b), (b, c), (c, a)))
    cross = np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    with np.errstate(divide="ignore"):
        radius = ab * bc * ca / (2.0 * cross)
    return float(radius.min())


def build(spec: TrackSpec) -> np.ndarray:
    centre = centre_line(spec)
    bend = min_bend_radius(centre)
    if bend < MIN_BEND_RADIUS:
        raise ValueError(f"{spec.name}: its tightest bend has a {bend:.2f} m radius")
    inner, outer = borders(centre, TRACK_WIDTH)
    array = np.hstack([centre, inner, outer]).astype(np.float64)
    validate_array(array)
    return array


def main() -> None:
    DATA_DIR.mkdir(parents=True, exist_ok=True)
    catalog = []
    for spec in SPECS:
        np.save(DATA_DIR / f"{spec.name}.npy", build(spec))
        entry = asdict(spec)
        del entry["harmonics"], entry["length"]
        catalog.append(entry)
    with open(DATA_DIR / "catalog.json", "w") as file:
        json.dump(catalog, file, indent=2)
        file.write("\n")


if __name__ == "__main__":
    main()
