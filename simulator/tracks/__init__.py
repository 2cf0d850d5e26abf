"""Race tracks in DeepRacer's format, with the geometry the simulator and reward params need.

A track file is a ``.npy`` float64 array of shape (N, 6): centre x, centre y, inner x, inner y,
outer x, outer y, in metres. A loop repeats its first row at the end. Built-in tracks live in
``data/`` with their metadata in ``data/catalog.json`` and a preview image each;
``python -m simulator.tracks.generate`` makes them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from functools import cache, cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"
MIN_POINTS = 10
DIRECTIONS = ("counterclockwise", "clockwise")


class TrackError(ValueError):
    """A track that cannot be raced on; the message says why, in a racer's words."""


class Projection(NamedTuple):
    """Where points fall on the centre line; every field is an array with one entry per point."""

    distance: np.ndarray  # [m] along the centre line from the start line, in [0, length)
    offset: np.ndarray  # [m] from the point to its projection
    is_left: np.ndarray  # bool: left of the centre line in the direction of travel
    segment: np.ndarray  # int: index of the waypoint behind the projection
    fraction: np.ndarray  # how far along that segment, 0..1
    half_width: np.ndarray  # [m] from the centre line to the border on the point's side
    width: np.ndarray  # [m] border to border, measured across the projection


@dataclass(frozen=True)
class Track:
    """A closed track: centre line and borders as (N, 2) arrays in metres, the loop closed.

    ``inner`` and ``outer`` keep their names whatever the direction; ``direction`` says which way
    the waypoints run ("counterclockwise" as built, or "clockwise" for the reversed track).
    """

    name: str
    display_name: str
    centre: np.ndarray
    inner: np.ndarray
    outer: np.ndarray
    description: str = ""
    difficulty: str = "intermediate"
    directions: tuple[str, ...] = DIRECTIONS
    direction: str = "counterclockwise"
    source: Path | None = field(default=None, compare=False)

    # Geometry

    @cached_property
    def _segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        starts = self.centre[:-1]
        vectors = np.diff(self.centre, axis=0)
        lengths_sq = np.maximum((vectors**2).sum(axis=1), 1e-12)
        cumulative = np.concatenate([[0.0], np.cumsum(np.sqrt(lengths_sq))])
        return starts, vectors, lengths_sq, cumulative

    @cached_property
    def _half_widths(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre-to-border distances on the left and on the right of travel, per waypoint."""
        tangent = np.gradient(self.centre, axis=0)
        to_inner = self.inner - self.centre
        inner_is_left = (tangent[:, 0] * to_inner[:, 1] - tangent[:, 1] * to_inner[:, 0]) > 0
        inner = np.linalg.norm(to_inner, axis=1)
        outer = np.linalg.norm(self.outer - self.centre, axis=1)
        return np.where(inner_is_left, inner, outer), np.where(inner_is_left, outer, inner)

    @property
    def length(self) -> float:
        """Length of the centre line [m]."""
        return float(self._segments[3][-1])

    @property
    def widths(self) -> np.ndarray:
        """Inner-to-outer border distance at each waypoint [m]."""
        left, right = self._half_widths
        return left + right

    @property
    def width(self) -> float:
        """Median width [m], the figure a racer reads on a track card."""
        return float(np.median(self.widths))

    @property
    def waypoints(self) -> list[tuple[float, float]]:
        """Centre-line points as DeepRacer's ``params["waypoints"]`` gives them."""
        return [(float(x), float(y)) for x, y in self.centre]

    def project_points(self, points: np.ndarray) -> Projection:
        """Project (k, 2) points onto the centre line, all at once."""
        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        starts, vectors, lengths_sq, cumulative = self._segments
        relative = points[:, None, :] - starts[None, :, :]
        fraction = np.clip((relative * vectors).sum(axis=2) / lengths_sq, 0.0, 1.0)
        nearest = starts + fraction[..., None] * vectors
        gap_sq = ((points[:, None, :] - nearest) ** 2).sum(axis=2)
        segment = gap_sq.argmin(axis=1)
        rows = np.arange(len(points))
        t = fraction[rows, segment]
        d = vectors[segment]
        r = relative[rows, segment]
        is_left = d[:, 0] * r[:, 1] - d[:, 1] * r[:, 0] > 0
        left, right = self._half_widths
        left_here = left[segment] + t * (left[segment + 1] - left[segment])
        right_here = right[segment] + t * (right[segment + 1] - right[segment])
        distance = cumulative[segment] + t * np.sqrt(lengths_sq[segment])
        return Projection(
            distance=np.mod(distance, self.length),
            offset=np.sqrt(gap_sq[rows, segment]),
            is_left=is_left,
            segment=segment,
            fraction=t,
            half_width=np.where(is_left, left_here, right_here),
            width=left_here + right_here,
        )

    def project(self, point) -> tuple[float, float, bool]:
        """(distance along the centre line from the start line, offset from it, left of it)."""
        p = self.project_points(point)
        return float(p.distance[0]), float(p.offset[0]), bool(p.is_left[0])

    def width_at(self, point) -> float:
        """Border-to-border width [m] across the centre point nearest to ``point``."""
        return float(self.project_points(point).width[0])

    def contains(self, point) -> bool:
        """Whether ``point`` is between the borders."""
        p = self.project_points(point)
        return bool(p.offset[0] <= p.half_width[0])

    def closest_waypoints(self, point) -> list[int]:
        """Indices of the waypoints behind and ahead of ``point`` (DeepRacer's convention)."""
        behind = int(self.project_points(point).segment[0])
        return [behind, self.next_waypoint(behind)]

    def next_waypoint(self, index: int) -> int:
        """The waypoint after ``index``; the repeated last point of a loop counts as the first."""
        return index + 1 if index + 1 < len(self.centre) - 1 else 0

    def point_at(self, distance: float | np.ndarray, offset: float | np.ndarray = 0.0):
        """(x, y, heading [rad]) at ``distance`` along the centre line, ``offset`` to the left."""
        starts, vectors, lengths_sq, cumulative = self._segments
        distance = np.mod(distance, self.length)
        segment = np.clip(
            np.searchsorted(cumulative, distance, side="right") - 1, 0, len(starts) - 1
        )
        t = (distance - cumulative[segment]) / np.sqrt(lengths_sq[segment])
        d = vectors[segment]
        heading = np.arctan2(d[..., 1], d[..., 0])
        x = starts[segment, 0] + t * d[..., 0] - offset * np.sin(heading)
        y = starts[segment, 1] + t * d[..., 1] + offset * np.cos(heading)
        return x, y, heading

    def with_direction(self, direction: str) -> Track:
        """This track driven ``direction``: clockwise reverses the waypoints."""
        if direction not in DIRECTIONS:
            raise TrackError(
                f"The direction must be one of {', '.join(DIRECTIONS)}, not {direction!r}."
            )
        if direction not in self.directions:
            raise TrackError(f"{self.display_name} cannot be driven {direction}.")
        if direction == self.direction:
            return self
        return replace(
            self,
            centre=self.centre[::-1].copy(),
            inner=self.inner[::-1].copy(),
            outer=self.outer[::-1].copy(),
            direction=direction,
        )

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The (min x, min y) and (max x, max y) corners of the track with its borders."""
        every = np.vstack([self.inner, self.outer])
        return every.min(axis=0), every.max(axis=0)


def names() -> list[str]:
    """The built-in tracks, in catalogue order."""
    return list(_catalog())


def load(name_or_path: str | Path) -> Track:
    """A built-in track by name, or a DeepRacer ``.npy`` file by path."""
    catalog = _catalog()
    if isinstance(name_or_path, str) and name_or_path in catalog:
        meta = catalog[name_or_path]
        return _from_array(
            np.load(DATA_DIR / f"{name_or_path}.npy"),
            name=name_or_path,
            display_name=meta["display_name"],
            description=meta["description"],
            difficulty=meta["difficulty"],
            directions=tuple(meta["directions"]),
            source=DATA_DIR / f"{name_or_path}.npy",
        )
    path = Path(name_or_path)
    if path.suffix != ".npy" or not path.is_file():
        known = ", ".join(catalog)
        raise TrackError(f"No track named {str(name_or_path)!r}. Built-in tracks: {known}.")
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise TrackError(f"{path.name} is not a NumPy .npy track file ({error}).") from None
    return _from_array(array, name=path.stem, display_name=path.stem, source=path)


def preview_path(name: str) -> Path:
    """The top-down preview image of a built-in track."""
    if name not in _catalog():
        raise TrackError(f"No track named {name!r}.")
    return DATA_DIR / f"{name}.png"


def validate_array(array: np.ndarray) -> None:
    """Raise ``TrackError`` unless ``array`` is a raceable DeepRacer track."""
    if array.ndim != 2 or array.shape[1] != 6:
        raise TrackError(
            f"A track file holds an (N, 6) array of centre, inner and outer points; "
            f"this one has shape {array.shape}."
        )
    if not np.issubdtype(array.dtype, np.number):
        raise TrackError(f"A track file holds numbers; this one holds {array.dtype}.")
    if len(array) < MIN_POINTS:
        raise TrackError(f"A track needs at least {MIN_POINTS} points; this one has {len(array)}.")
    if not np.isfinite(array).all():
        raise TrackError("The track file contains NaN or infinite coordinates.")
    for column, border in ((2, "inner"), (4, "outer")):
        if _self_intersects(array[:, column : column + 2]):
            raise TrackError(f"The {border} border of this track crosses itself.")
    if _segments_cross(array[:, 2:4], array[:, 4:6]):
        raise TrackError("The inner and outer borders of this track cross each other.")


def _from_array(array: np.ndarray, **metadata: object) -> Track:
    validate_array(array)
    array = np.asarray(array, dtype=np.float64)
    if not np.allclose(array[0], array[-1]):
        array = np.vstack([array, array[:1]])
    # Drop repeated points: they make zero-length segments with no direction.
    keep = np.concatenate([[True], np.linalg.norm(np.diff(array[:, :2], axis=0), axis=1) > 1e-9])
    array = array[keep]
    return Track(centre=array[:, 0:2], inner=array[:, 2:4], outer=array[:, 4:6], **metadata)  # type: ignore[arg-type]


def _self_intersects(line: np.ndarray) -> bool:
    """Whether any two non-adjacent segments of a closed polyline cross."""
    points = line if np.allclose(line[0], line[-1]) else np.vstack([line, line[:1]])
    return _segments_cross(points, points, same=True)


def _segments_cross(first: np.ndarray, second: np.ndarray, *, same: bool = False) -> bool:
    """Whether a segment of polyline ``first`` crosses one of ``second`` (both (n, 2) arrays)."""
    a, b = first[:-1], first[1:]
    c, d = second[:-1], second[1:]

    def orientation(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return np.sign(
            (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
            - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
        )

    if same:  # every pair (i, j), i < j, that does not share an end point
        count = len(a)
        i, j = np.triu_indices(count, k=2)
        keep = ~((i == 0) & (j == count - 1))
        i, j = i[keep], j[keep]
    else:
        i, j = (index.ravel() for index in np.meshgrid(np.arange(len(a)), np.arange(len(c))))
    crosses = (orientation(a[i], b[i], c[j]) != orientation(a[i], b[i], d[j])) & (
        orientation(c[j], d[j], a[i]) != orientation(c[j], d[j], b[i])
    )
    return bool(crosses.any())


@cache
def _catalog() -> dict[str, dict]:
    with open(DATA_DIR / "catalog.json") as file:
        return {entry["name"]: entry for entry in json.load(file)}
