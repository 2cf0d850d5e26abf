"""Race tracks in DeepRacer's format.

A track file is a ``.npy`` float64 array of shape (N, 6): centre x, centre y, inner x, inner y,
outer x, outer y, in metres. A loop repeats its first row at the end. Built-in tracks live in
``data/`` with their metadata in ``data/catalog.json``; ``generate.py`` beside this file makes them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"
MIN_POINTS = 10
DIRECTIONS = ("counterclockwise", "clockwise")


class TrackError(ValueError):
    """A track file that cannot be raced on; the message says why, in a racer's words."""


@dataclass(frozen=True)
class Track:
    """A closed track: centre line and borders as (N, 2) arrays in metres, the loop closed."""

    name: str
    display_name: str
    centre: np.ndarray
    inner: np.ndarray
    outer: np.ndarray
    description: str = ""
    difficulty: str = "intermediate"
    directions: tuple[str, ...] = DIRECTIONS
    source: Path | None = field(default=None, compare=False)

    @property
    def length(self) -> float:
        """Length of the centre line [m]."""
        return float(np.linalg.norm(np.diff(self.centre, axis=0), axis=1).sum())

    @property
    def widths(self) -> np.ndarray:
        """Inner-to-outer border distance at each centre point [m]."""
        return np.linalg.norm(self.outer - self.inner, axis=1)

    @property
    def width(self) -> float:
        """Median width [m], the figure a racer reads on a track card."""
        return float(np.median(self.widths))

    @property
    def waypoints(self) -> list[tuple[float, float]]:
        """Centre-line points as DeepRacer's ``params["waypoints"]`` gives them."""
        return [(float(x), float(y)) for x, y in self.centre]


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


def _from_array(array: np.ndarray, **metadata: object) -> Track:
    validate_array(array)
    array = np.asarray(array, dtype=np.float64)
    if not np.allclose(array[0], array[-1]):
        array = np.vstack([array, array[:1]])
    return Track(centre=array[:, 0:2], inner=array[:, 2:4], outer=array[:, 4:6], **metadata)  # type: ignore[arg-type]


def _self_intersects(line: np.ndarray) -> bool:
    """Whether any two non-adjacent segments of a closed polyline cross."""
    points = line if np.allclose(line[0], line[-1]) else np.vstack([line, line[:1]])
    a, b = points[:-1], points[1:]
    count = len(a)

    def orientation(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return np.sign(
            (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
            - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
        )

    # Every pair of segments (i, j), i < j, at once.
    i, j = np.triu_indices(count, k=2)
    keep = ~((i == 0) & (j == count - 1))  # the first and last segments share the start point
    i, j = i[keep], j[keep]
    crosses = (orientation(a[i], b[i], a[j]) != orientation(a[i], b[i], b[j])) & (
        orientation(a[j], b[j], a[i]) != orientation(a[j], b[j], b[i])
    )
    return bool(crosses.any())


@cache
def _catalog() -> dict[str, dict]:
    with open(DATA_DIR / "catalog.json") as file:
        return {entry["name"]: entry for entry in json.load(file)}
