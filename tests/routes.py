"""DeepRacer-format route files for tests, made here (none of DeepRacer's own files are copied).

A route file is what ``numpy.save`` writes of a float64 (N, 6) array: centre x, centre y, inner
border x, inner border y, outer border x, outer border y, in metres, the first row repeated at the
end to close the loop. Each function returns the array of one kind of file; ``ROUTES`` names them
all, and ``python -m tests.routes DIR`` writes every one into DIR as ``NAME.npy``.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

WIDTH = 1.0668  # [m] DeepRacer's usual track width (42 inches)


def counterclockwise(points: int = 60, radii: tuple[float, float] = (4.0, 2.5)) -> np.ndarray:
    """An elliptical loop whose points run counter-clockwise, the closing point repeated."""
    theta = np.linspace(0.0, 2.0 * np.pi, points, endpoint=False)
    centre = np.column_stack([radii[0] * np.cos(theta), radii[1] * np.sin(theta)])
    tangent = np.gradient(np.vstack([centre[-1:], centre, centre[:1]]), axis=0)[1:-1]
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])  # towards the inside of the loop
    inner, outer = centre + left * WIDTH / 2, centre - left * WIDTH / 2
    ring = np.hstack([centre, inner, outer])
    return np.vstack([ring, ring[:1]]).astype(np.float64)


def clockwise() -> np.ndarray:
    """The same loop, its points running clockwise (its inner border still the inner one)."""
    return counterclockwise()[::-1].copy()


def repeated_point() -> np.ndarray:
    """A waypoint written twice in a row, as in some of DeepRacer's own files."""
    route = counterclockwise()
    return np.insert(route, 21, route[20], axis=0)


def repeated_border_point() -> np.ndarray:
    """The centre moves on while the inner border stays put for a step (a zero-length segment)."""
    route = counterclockwise()
    route[31, 2:4] = route[30, 2:4]
    return route


def repeated_closing_point() -> np.ndarray:
    """The closing point written twice."""
    route = counterclockwise()
    return np.vstack([route, route[:1]])


def open_loop() -> np.ndarray:
    """A loop whose file leaves out the closing point."""
    return counterclockwise()[:-1].copy()


def border_crosses_itself() -> np.ndarray:
    """The inner border has a kink: two of its points swapped, so it crosses itself."""
    route = counterclockwise()
    route[[10, 11], 2:4] = route[[11, 10], 2:4]
    return route


def borders_cross() -> np.ndarray:
    """The inner and outer borders swap sides for a stretch, so they cross each other."""
    route = counterclockwise()
    route[25:35, 2:4], route[25:35, 4:6] = route[25:35, 4:6].copy(), route[25:35, 2:4].copy()
    return route


def not_a_number() -> np.ndarray:
    """One coordinate is NaN."""
    route = counterclockwise()
    route[7, 3] = np.nan
    return route


def wrong_shape() -> np.ndarray:
    """Centre and inner border only: four columns."""
    return counterclockwise()[:, :4].copy()


def too_few_points() -> np.ndarray:
    """Only two different points, each repeated."""
    route = counterclockwise(points=4)
    return np.vstack([route[0], route[0], route[1], route[1], route[0]])


def straight() -> np.ndarray:
    """An open straight line that never comes back to its start (a drag strip)."""
    x = np.linspace(0.0, 20.0, 41)
    zeros, half = np.zeros_like(x), np.full_like(x, WIDTH / 2)
    return np.column_stack([x, zeros, x, half, x, -half])


ROUTES: dict[str, Callable[[], np.ndarray]] = {
    "counterclockwise": counterclockwise,
    "clockwise": clockwise,
    "repeated_point": repeated_point,
    "repeated_border_point": repeated_border_point,
    "repeated_closing_point": repeated_closing_point,
    "open_loop": open_loop,
    "border_crosses_itself": border_crosses_itself,
    "borders_cross": borders_cross,
    "not_a_number": not_a_number,
    "wrong_shape": wrong_shape,
    "too_few_points": too_few_points,
    "straight": straight,
}


def route_bytes(name: str) -> bytes:
    """The ``.npy`` file of route ``name`` as bytes, as an upload brings it."""
    import io

    buffer = io.BytesIO()
    np.save(buffer, ROUTES[name]())
    return buffer.getvalue()


def write(directory: Path) -> list[Path]:
    """Write every route into ``directory``; the paths written."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name, make in ROUTES.items():
        path = directory / f"{name}.npy"
        np.save(path, make())
        written.append(path)
    return written


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python -m tests.routes DIR")
    for path in write(Path(sys.argv[1])):
        sys.stdout.write(f"{path}\n")
