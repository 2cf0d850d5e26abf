"""Race tracks in DeepRacer's format, with the geometry the simulator and reward params need.

A track file is a ``.npy`` float64 array of shape (N, 6): centre x, centre y, inner x, inner y,
outer x, outer y, in metres. A loop repeats its first row at the end. Built-in tracks live in
``data/`` with their metadata in ``data/catalog.json`` and a preview image each;
``python -m simulator.tracks.generate`` makes them. Other tracks come as a file path, inline (a
mapping with the file's bytes, which crosses to a sandbox child), or by name through a resolver
the application registers (the training app's reads its Track table). Routes load as DeepRacer's
loader takes them: repeated points dropped, the file's own direction read from it.

Long because the loader follows DeepRacer's (track_data.py) check by check, beside the geometry
every part of the simulator reads (projection onto the centre line, borders, closest waypoints).
"""

from __future__ import annotations

import io
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import cache, cached_property
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

DATA_DIR = Path(__file__).resolve().parent / "data"
DEEPRACER_DIR = DATA_DIR / "deepracer"  # DeepRacer's catalogue: see its NOTICE and deepracer.py
MIN_POINTS = 3  # different waypoints: the fewest that close a loop
REPEAT = 1e-9  # [m] a centre point that moved no further repeats the one before it
GRID_CELLS = 4  # grid cells a border segment covers, on average, in the crossing check
GRID_PAIRS = 50_000_000  # segment pairs the crossing check may compare: a few seconds
GRID_BATCH = 100_000  # grid entries whose pairs are compared at once (bounds the memory)
OPEN_GAP = 3.0  # a route whose end is this many of its longest steps from its start is open
DIRECTIONS = ("counterclockwise", "clockwise")
# The .npy format versions numpy.save writes for a plain array, and their header readers.
NPY_HEADERS = {
    (1, 0): np.lib.format.read_array_header_1_0,
    (2, 0): np.lib.format.read_array_header_2_0,
}


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
    the waypoints run ("counterclockwise" or "clockwise", read from the route as loaded), and
    ``with_direction`` turns them to run the other way: onto the route file DeepRacer drives that
    way where ``routes`` names one (``world_name`` is the file loaded), else by reversing them;
    ``reversed`` says the waypoints run against the route file's own order (DeepRacer's
    ``REVERSE_DIR``). ``season`` is the year DeepRacer raced it (None: one of Pitlane's own).
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
    reversed: bool = False
    source: Path | None = field(default=None, compare=False)
    season: int | None = None
    world_name: str = ""
    routes: Mapping[str, str] = field(default_factory=dict, compare=False)

    # Geometry

    @cached_property
    def _segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        starts = self.centre[:-1]
        vectors = np.diff(self.centre, axis=0)
        lengths_sq = np.maximum((vectors**2).sum(axis=1), 1e-12)
        cumulative = np.concatenate([[0.0], np.cumsum(np.sqrt(lengths_sq))])
        return starts, vectors, lengths_sq, cumulative

    @cached_property
    def half_widths(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre-to-border distances on the left and on the right of travel, per waypoint."""
        tangent = np.gradient(self.centre, axis=0)
        to_inner = self.inner - self.centre
        inner_is_left = (tangent[:, 0] * to_inner[:, 1] - tangent[:, 1] * to_inner[:, 0]) > 0
        inner = np.linalg.norm(to_inner, axis=1)
        outer = np.linalg.norm(self.outer - self.centre, axis=1)
        return np.where(inner_is_left, inner, outer), np.where(inner_is_left, outer, inner)

    @property
    def along(self) -> np.ndarray:
        """[m] each waypoint's distance along the centre line from the first."""
        return self._segments[3]

    @property
    def length(self) -> float:
        """Length of the centre line [m]."""
        return float(self.along[-1])

    @property
    def widths(self) -> np.ndarray:
        """Inner-to-outer border distance at each waypoint [m]."""
        left, right = self.half_widths
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
        left, right = self.half_widths
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
        route = self.routes.get(direction)
        if route and route != self.world_name:
            return _builtin(self.name, route).with_direction(direction)
        return replace(
            self,
            centre=self.centre[::-1].copy(),
            inner=self.inner[::-1].copy(),
            outer=self.outer[::-1].copy(),
            direction=direction,
            reversed=not self.reversed,
        )

    def on_route(self, world_name: str) -> Track:
        """This track on its route file ``world_name``, held to it: ``with_direction`` reverses
        that file's waypoints rather than moving to the file the console drives the other way.
        That is how simapp drives a WORLD_NAME: the file of that name, in its own order or, with
        REVERSE_DIR, reversed (bundle/markov/track_geom/track_data.py:104-105, 185 and 195,
        01f5f01; the name is suffixed _cw/_ccw only where TRACK_DIRECTION_CLOCKWISE is given,
        bundle/markov/boto/s3/files/yaml_file.py:228-246). DeepRacer for Cloud gives one bare
        (defaults/template-worker.env:1, DR_WORLD_NAME=reInvent2019_track), and
        reInvent2019_track.npy holds 154 waypoints where reInvent2019_track_ccw.npy, the
        console's, holds 79. ``TrackError`` for a name that is not one of this track's route
        files."""
        found = world(world_name)
        if found is None or found[0] != self.name:
            raise TrackError(f"{world_name} is not one of {self.display_name}'s route files.")
        return replace(_builtin(self.name, world_name), routes={})

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The (min x, min y) and (max x, max y) corners of the track with its borders."""
        every = np.vstack([self.inner, self.outer])
        return every.min(axis=0), every.max(axis=0)


def names(*, origin: str | None = None) -> list[str]:
    """The built-in tracks, in catalogue order: Pitlane's own then DeepRacer's, or those of one
    ``origin`` ("pitlane": made by generate.py; "deepracer": brought by deepracer.py)."""
    return [name for name, entry in _catalog().items() if origin in (None, entry["origin"])]


def world(world_name: str) -> tuple[str, str] | None:
    """The built-in track a DeepRacer ``WORLD_NAME`` (a route file's name) is, and the direction
    that file is driven: ``2022_april_open_cw`` is ("2022_april_open", "clockwise"); None for a
    name that is not one of DeepRacer's route files."""
    for name, entry in _catalog().items():
        if world_name in entry.get("world_names", ()):
            return name, entry["world_names"][world_name]
    return None


def surroundings(world_name: str) -> dict | None:
    """What stands round DeepRacer's world ``world_name`` (its field, the field's edge, its sky:
    read from simapp's meshes by surroundings.py), or None for a world that is not DeepRacer's."""
    return _surroundings().get(world_name)


@cache
def _surroundings() -> dict[str, dict]:
    with open(DEEPRACER_DIR / "surroundings.json") as file:
        return json.load(file)


def driven(
    source: str | Path | Mapping[str, Any], direction: str, route: str | None = None
) -> Track:
    """Track ``source`` (as ``load`` takes it) as a car drives it ``direction``: on its route file
    ``route`` (a WORLD_NAME, held to it: ``Track.on_route``), or, where None, on the file the
    console drives that way. What the environment drives, and so what replays of its driving
    read (a model's: ``training.models.RLModel.driven_track``)."""
    loaded = load(source)
    return (loaded if route is None else loaded.on_route(route)).with_direction(direction)


def deepracer_world(name: str, direction: str) -> tuple[str, bool]:
    """(WORLD_NAME, REVERSE_DIR) that have DeepRacer drive track ``name`` ``direction``, as a
    training_params.yaml says it: the route file DeepRacer drives that way where there is one
    (``2022_april_open`` clockwise is ``2022_april_open_cw``, not reversed, the name simapp's
    yaml_file.py:228-246 writes back), else the track's own file, reversed when it runs the
    other way (``Albert`` clockwise is ``Albert`` as it is: its file runs clockwise)."""
    track = load(name)
    route = track.routes.get(direction)
    if route:
        return route, False
    return (track.world_name or track.name), direction != track.direction


def entry(name: str) -> dict:
    """A built-in track's catalogue entry (display name, directions, season, length and width
    [m] for DeepRacer's, ...), for lists that need no geometry; ``TrackError`` when unknown."""
    try:
        return _catalog()[name]
    except KeyError:
        raise TrackError(f"No track named {name!r}.") from None


Resolver = Callable[[str], "Mapping[str, Any] | None"]
_resolvers: list[Resolver] = []


def register_resolver(resolver: Resolver) -> None:
    """Let ``load(name)`` find tracks that are not built in: ``resolver(name)`` returns an inline
    track (see ``load``) or None. The training app registers one that reads its Track table."""
    if resolver not in _resolvers:
        _resolvers.append(resolver)


def unregister_resolver(resolver: Resolver) -> None:
    if resolver in _resolvers:
        _resolvers.remove(resolver)


def inline(name: str) -> str | dict[str, Any]:
    """``name`` as a process without the resolvers (a sandbox child) can load it: an added track
    becomes its inline form (route bytes and metadata); a built-in or unknown name stays a name
    (an unknown one fails where it is loaded, with the usual message)."""
    if name in _catalog():
        return name
    for resolver in _resolvers:
        found = resolver(name)
        if found is not None:
            return dict(found)
    return name


def load(source: str | Path | Mapping[str, Any]) -> Track:
    """A track from a built-in name, a track name a registered resolver knows, a DeepRacer
    ``.npy`` file by path, or an inline track: a mapping with ``name``, ``route`` (the ``.npy``
    file's bytes, or the array itself) and optionally ``display_name``, ``directions``,
    ``description`` and ``difficulty``."""
    if isinstance(source, Mapping):
        return _from_inline(source)
    catalog = _catalog()
    if isinstance(source, str) and source in catalog:
        return _builtin(source)
    found = world(source) if isinstance(source, str) else None
    if found is not None:  # a WORLD_NAME: its track, driven as that file is
        return _builtin(found[0], source).with_direction(found[1])
    if isinstance(source, str) and not source.endswith(".npy"):
        for resolver in _resolvers:
            found = resolver(source)
            if found is not None:
                return _from_inline(found)
    path = Path(source)
    if path.suffix != ".npy" or not path.is_file():
        known = ", ".join(names(origin="pitlane"))
        raise TrackError(
            f"No track named {str(source)!r}. Built-in tracks: {known}, and DeepRacer's "
            f"{len(names(origin='deepracer'))} by their WORLD_NAME, like reInvent2019_track."
        )
    return _from_array(
        read_route(path.read_bytes(), path.name),
        name=path.stem,
        display_name=path.stem,
        source=path,
    )


def read_route(data: bytes, filename: str = "The route file") -> np.ndarray:
    """The array in a DeepRacer route file's bytes (a NumPy ``.npy`` file, no pickles). Its
    header is read first: numpy sets aside the memory a header claims before reading a value, and
    a header may claim any shape ((10**12, 6): 43.7 TiB), so an array that the file's bytes do not
    hold is refused before that."""
    stream = io.BytesIO(data)
    try:
        version = np.lib.format.read_magic(stream)
        shape, _, dtype = NPY_HEADERS[version](stream)
    except (KeyError, OSError, ValueError, EOFError):
        if data.startswith(b"PK"):  # numpy.savez's zip
            raise TrackError(f"{filename} holds several arrays; a route file holds one.") from None
        raise TrackError(
            f"{filename} is not a NumPy .npy track file: DeepRacer route files are saved with "
            "numpy.save."
        ) from None
    values, held = math.prod(shape), len(data) - stream.tell()
    if values * max(dtype.itemsize, 1) > held:
        raise TrackError(
            f"{filename} is cut short or damaged: its header says it holds {values:,} values "
            f"(shape {shape}), which take {values * dtype.itemsize:,} bytes, and {held:,} bytes "
            "follow the header."
        )
    try:
        return np.load(io.BytesIO(data), allow_pickle=False)
    except (OSError, ValueError, EOFError):  # values that only a pickle holds
        raise TrackError(f"{filename} holds values that are not numbers.") from None


def preview_path(name: str) -> Path:
    """The top-down preview image of a built-in track."""
    return entry(name)["folder"] / f"{name}.png"


def validate_array(array: np.ndarray) -> None:
    """Raise ``TrackError`` unless ``array`` is a raceable DeepRacer track."""
    _sanitized(array)


def signed_area(ring: np.ndarray) -> float:
    """Shoelace area of a closed (n, 2) polyline: positive when its points run counter-clockwise."""
    x, y = ring[:, 0], ring[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


COLUMNS = (
    "centre x",
    "centre y",
    "inner border x",
    "inner border y",
    "outer border x",
    "outer border y",
)


def _sanitized(array: np.ndarray) -> np.ndarray:
    """The route as a closed (n, 6) float64 loop, repeated points dropped; ``TrackError`` says
    what is wrong with a route DeepRacer would refuse, or one whose borders cross.

    Follows DeepRacer's loader, simapp bundle/markov/track_geom/track_data.py (01f5f01).
    """
    array = np.asarray(array)
    # Shape: two rows of at least six columns (track_data.py:246-249); further columns are unused.
    if array.ndim != 2 or array.shape[0] < 2 or array.shape[1] < 6:
        raise TrackError(
            "A route file holds one row per waypoint with six numbers: centre x, centre y, "
            "inner border x, inner border y, outer border x, outer border y, in metres. "
            f"This one has shape {array.shape}."
        )
    if not (np.issubdtype(array.dtype, np.floating) or np.issubdtype(array.dtype, np.integer)):
        raise TrackError(f"A route file holds numbers; this one holds {array.dtype} values.")
    # Every coordinate finite (track_data.py:251-258).
    core = array[:, :6].astype(np.float64)
    if not np.isfinite(core).all():
        row, column = (int(i) for i in np.argwhere(~np.isfinite(core))[0])
        raise TrackError(
            f"Waypoint {row} of the route file has NaN or infinity for its {COLUMNS[column]}; "
            "every coordinate is a number of metres."
        )
    # A loop repeats its first row, every column, at the end (track_data.py:201, 260); the
    # repeated points dropped are consecutive rows whose centre moved <= 1e-9 m, keeping the
    # first, and the closing row is kept apart from them (track_data.py:263-276).
    is_loop = bool(np.all(array[0] == array[-1]))
    body = core[:-1] if is_loop and len(core) > 2 else core
    keep = np.ones(len(body), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(body[:, :2], axis=0), axis=1) > REPEAT
    body = body[keep]
    # The closing point, repeated once or more, or a last centre point back at the first: the loop
    # closes there. (DeepRacer drives a route that does not close as an open line; ours are loops.)
    while len(body) > 1 and np.linalg.norm(body[-1, :2] - body[0, :2]) <= REPEAT:
        body = body[:-1]
    # A loop needs three different points (shapely's LinearRing, track_data.py:202-204).
    if len(body) < MIN_POINTS:
        raise TrackError(
            f"A track needs at least {MIN_POINTS} different waypoints; this route has "
            f"{len(body)} once repeated points are left out."
        )
    if not is_loop:
        steps = np.linalg.norm(np.diff(body[:, :2], axis=0), axis=1)
        if np.linalg.norm(body[-1, :2] - body[0, :2]) > OPEN_GAP * steps.max():
            raise TrackError(
                "This route does not come back to where it starts: it is an open line, like "
                "DeepRacer's straight drag track, and tracks here are loops. Its last waypoint "
                "should lead back to the first."
            )
    route = np.vstack([body, body[:1]])
    _check_borders(route)
    return route


def _check_borders(route: np.ndarray) -> None:
    """DeepRacer does not check the borders (the report's "no is_valid check"); a border that
    crosses itself or the other one has no inside, so we refuse it with the waypoint it is at."""
    for column, border in ((2, "inner"), (4, "outer")):
        crossing = _first_crossing(route[:, column : column + 2], None)
        if crossing is not None:
            raise TrackError(
                f"The {border} border of this track crosses itself (between waypoints "
                f"{crossing[0]} and {crossing[1]})."
            )
    crossing = _first_crossing(route[:, 2:4], route[:, 4:6])
    if crossing is not None:
        raise TrackError(
            "The inner and outer borders of this track cross each other (inner border near "
            f"waypoint {crossing[0]}, outer border near waypoint {crossing[1]})."
        )


def _from_array(array: np.ndarray, **metadata: Any) -> Track:
    route = _sanitized(array)
    centre = route[:, 0:2]
    # Which way the file's points run: the sign of the centre line's area, as DeepRacer reads
    # shapely's LinearRing.is_ccw of it (track_data.py:222).
    direction = "counterclockwise" if signed_area(centre[:-1]) > 0 else "clockwise"
    return Track(
        centre=centre, inner=route[:, 2:4], outer=route[:, 4:6], direction=direction, **metadata
    )


def _from_inline(spec: Mapping[str, Any]) -> Track:
    name = str(spec.get("name") or "track")
    route = spec.get("route")
    if isinstance(route, (bytes, bytearray, memoryview)):
        array = read_route(bytes(route), f"The route file of {name}")
    elif route is None:
        raise TrackError(f"The track {name!r} comes with no route.")
    else:
        try:
            array = np.asarray(route, dtype=np.float64)
        except (TypeError, ValueError):
            raise TrackError(f"The route of {name!r} is not a table of numbers.") from None
    directions = tuple(spec.get("directions") or DIRECTIONS)
    unknown = [d for d in directions if d not in DIRECTIONS]
    if unknown:
        raise TrackError(
            f"A track is driven {' or '.join(DIRECTIONS)}, not {', '.join(map(str, unknown))}."
        )
    return _from_array(
        array,
        name=name,
        display_name=str(spec.get("display_name") or name),
        description=str(spec.get("description") or ""),
        difficulty=str(spec.get("difficulty") or "intermediate"),
        directions=directions,
    )


def _first_crossing(first: np.ndarray, second: np.ndarray | None) -> tuple[int, int] | None:
    """The first pair of segments (i, j), by i then j, where polyline ``first`` properly crosses
    ``second``, or crosses itself when ``second`` is None; None if none cross.

    Only a proper crossing counts, the two segments passing through each other: segments that
    merely touch (at a shared or repeated point, or end to end) and zero-length segments, which
    repeated points make, never count. Only segments near each other are compared
    (``_near_pairs``): comparing each with every other took minutes for a route of 174,000
    waypoints, inside the transaction that adds the track.
    """
    a, b = first[:-1], first[1:]
    same = second is None
    c, d = (a, b) if same else (second[:-1], second[1:])
    best = None
    for i, j in _near_pairs(a, b, c, d):
        if same:  # each pair once, and not a segment with itself
            keep = j > i
            i, j = i[keep], j[keep]
        o1, o2 = _orientation(a[i], b[i], c[j]), _orientation(a[i], b[i], d[j])
        o3, o4 = _orientation(c[j], d[j], a[i]), _orientation(c[j], d[j], b[i])
        hits = np.flatnonzero((o1 * o2 < 0) & (o3 * o4 < 0))
        if len(hits):
            hit = min(zip(i[hits].tolist(), j[hits].tolist(), strict=True))
            best = hit if best is None else min(best, hit)
    return best


def _near_pairs(a, b, c, d):
    """Batches (i, j) of segments a[i]-b[i] and c[j]-d[j] whose bounding boxes share a cell of a
    square grid: every pair whose boxes meet is among them (some more than once). The cell is
    twice the median segment's size, doubled until the boxes cover at most ``GRID_CELLS`` cells
    a segment (a long straight does not fill the grid); ``TrackError`` when the waypoints crowd
    so that more than ``GRID_PAIRS`` pairs would be compared, which no drawn track comes near."""
    low1, high1 = np.minimum(a, b), np.maximum(a, b)
    low2, high2 = np.minimum(c, d), np.maximum(c, d)
    origin = np.minimum(low1.min(axis=0), low2.min(axis=0))
    extent = float((np.maximum(high1.max(axis=0), high2.max(axis=0)) - origin).max())
    sides = np.concatenate([(high1 - low1).max(axis=1), (high2 - low2).max(axis=1)])
    # Twice the median segment, so that most boxes fall in one or two cells (measured: the
    # largest upload's check takes half the time of a cell the median's size); at most 2**24
    # cells a side, so a cell's number fits in 64 bits.
    size = max(2 * float(np.median(sides)), extent / 2**24, 1e-9)
    while _cell_count(low1, high1, origin, size) + _cell_count(
        low2, high2, origin, size
    ) > GRID_CELLS * (len(a) + len(c)):
        size *= 2
    cells1, segments1 = _cells(low1, high1, origin, size)
    cells2, segments2 = _cells(low2, high2, origin, size)
    order = np.argsort(cells2, kind="stable")
    cells2, segments2 = cells2[order], segments2[order]
    begin = np.searchsorted(cells2, cells1, side="left")
    count = np.searchsorted(cells2, cells1, side="right") - begin
    if int(count.sum()) > GRID_PAIRS:
        raise TrackError(
            "This route's waypoints crowd too closely to check that its borders do not cross; "
            "a route's waypoints are usually spaced some centimetres apart."
        )
    for start in range(0, len(cells1), GRID_BATCH):
        n = count[start : start + GRID_BATCH]
        total = int(n.sum())
        if not total:
            continue
        offset = np.arange(total) - np.repeat(np.cumsum(n) - n, n)
        i = np.repeat(segments1[start : start + GRID_BATCH], n)
        yield i, segments2[np.repeat(begin[start : start + GRID_BATCH], n) + offset]


def _cell_span(low: np.ndarray, high: np.ndarray, origin: np.ndarray, size: float):
    first = np.floor((low - origin) / size).astype(np.int64)
    return first, np.floor((high - origin) / size).astype(np.int64) - first + 1


def _cell_count(low: np.ndarray, high: np.ndarray, origin: np.ndarray, size: float) -> int:
    _, span = _cell_span(low, high, origin, size)
    return int((span[:, 0] * span[:, 1]).sum())


def _cells(low: np.ndarray, high: np.ndarray, origin: np.ndarray, size: float):
    """(cell, segment) for every grid cell each box covers, a cell numbered by one integer."""
    first, span = _cell_span(low, high, origin, size)
    count = span[:, 0] * span[:, 1]
    segment = np.repeat(np.arange(len(low)), count)
    k = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    x = first[segment, 0] + k % span[segment, 0]
    y = first[segment, 1] + k // span[segment, 0]
    return (x << 24) + y, segment


def _orientation(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Sign of the turn p -> q -> r: 1 left, -1 right, 0 in line (exactly, for a repeated point)."""
    return np.sign(
        (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
        - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])
    )


def _builtin(name: str, route: str | None = None) -> Track:
    """A catalogue track on ``route`` (a WORLD_NAME it drives; its first direction's when None)."""
    meta = _catalog()[name]
    routes = meta.get("routes", {})
    route = route or routes.get(meta["directions"][0], name)
    path = meta["folder"] / ("routes" if routes else "") / f"{route}.npy"
    return _from_array(
        np.load(path),
        name=name,
        display_name=meta["display_name"],
        description=meta["description"],
        difficulty=meta["difficulty"],
        directions=tuple(meta["directions"]),
        source=path,
        season=meta.get("season"),
        world_name=route,
        routes=routes,
    )


@cache
def _catalog() -> dict[str, dict]:
    """Pitlane's tracks (``catalog.json``, made by generate.py), then DeepRacer's."""
    found = {}
    for origin, folder in (("pitlane", DATA_DIR), ("deepracer", DEEPRACER_DIR)):
        with open(folder / "catalog.json") as file:
            for item in json.load(file):
                found[item["name"]] = {"season": None, **item, "folder": folder, "origin": origin}
    return found
