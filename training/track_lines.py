"""A track's racing line as the console shows it (issue 59; ``simulator.racing_line``).

A built-in track's line without a margin is stored with the simulator and read from there. Every
other line (an added track's, or any track's with a margin) is a ``TrackLine`` row, computed by a
worker (the ``training.racing_line`` task, in ``training.tasks``): a page that asks for one not
yet computed, or computed from another track, car or method, requests it and says it is being
computed. Adding a track requests its lines at once (``track_lines_request_all``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import timedelta

import numpy as np
from django.db import transaction
from django.utils import timezone

from common import queueing
from simulator import racing_line
from simulator import tracks as simulator_tracks
from simulator.car import CarSpec
from training import lifecycle
from training.models import Track, TrackLine

log = logging.getLogger(__name__)

COMPUTE = "training.racing_line"  # the task, by name (common.queueing)
# A request still computing after this long was lost with its worker: it is sent again. The
# longest built-in track's line takes about 10 s of CPU.
LOST_AFTER = timedelta(minutes=10)
LITERAL_STRIDE = 2  # every second point of the line (0.2 m apart) in a reward function's copy


@dataclass(frozen=True)
class LineShown:
    """A track's line in one direction and margin as a page shows it: ``line`` when ``status``
    is "ready"; "computing" while a worker computes it; "failed" with ``message`` in words."""

    track: Track
    geometry: simulator_tracks.Track  # the simulator's, driven ``direction``
    direction: str
    margin_cm: int
    status: str
    line: racing_line.RacingLine | None = None
    message: str = ""


def track_line(*, track: Track, direction: str, margin_cm: int = 0) -> LineShown:
    """``track``'s racing line driven ``direction`` ``margin_cm`` inside the borders: the stored
    one, or its row; requested (and "computing") where there is none or it is stale."""
    geometry = _geometry(track, direction)
    line = _stored(track, geometry, margin_cm)
    if line is not None:
        return LineShown(track, geometry, direction, 0, TrackLine.Status.READY, line)
    key = _key(geometry, margin_cm)
    row = TrackLine.objects.filter(track=track, direction=direction, margin_cm=margin_cm).first()
    lost = timezone.now() - LOST_AFTER
    if (
        row is None
        or row.key != key
        or (row.status == TrackLine.Status.COMPUTING and row.requested_at < lost)
    ):
        track_line_request(track=track, direction=direction, margin_cm=margin_cm, key=key)
        return LineShown(track, geometry, direction, margin_cm, TrackLine.Status.COMPUTING)
    if row.status != TrackLine.Status.READY:
        return LineShown(track, geometry, direction, margin_cm, row.status, message=row.message)
    array = row.array.astype(np.float64)
    line = racing_line.RacingLine(
        array[:, :2], array[:, 2], row.lap_time, row.standing_lap_time, margin_cm / 100
    )
    return LineShown(track, geometry, direction, margin_cm, TrackLine.Status.READY, line)


def line_times(*, track: Track, direction: str) -> tuple[float, float] | None:
    """(from a standing start, flying) [s]: the laps of ``track``'s line driven ``direction``
    without a margin, where it is computed and current; None otherwise (and where the track's
    route cannot be read). Reads only."""
    try:
        geometry = _geometry(track, direction)
    except simulator_tracks.TrackError:
        return None
    line = _stored(track, geometry, 0)
    if line is not None:
        return line.standing_lap_time, line.lap_time
    found = TrackLine.objects.filter(
        track=track,
        direction=direction,
        margin_cm=0,
        key=_key(geometry, 0),
        status=TrackLine.Status.READY,
    )
    return found.values_list("standing_lap_time", "lap_time").first()


def _geometry(track: Track, direction: str) -> simulator_tracks.Track:
    """The simulator's ``track`` driven ``direction`` (``TrackError`` where it cannot be)."""
    return simulator_tracks.load(track.name).with_direction(direction)


def _stored(
    track: Track, geometry: simulator_tracks.Track, margin_cm: int
) -> racing_line.RacingLine | None:
    """A built-in track's line stored with the simulator, where it is current and no margin is
    asked for; None otherwise (the line is then a ``TrackLine`` row's)."""
    if track.builtin and margin_cm == 0:
        return racing_line.stored_line(geometry)
    return None


def _key(geometry: simulator_tracks.Track, margin_cm: int) -> str:
    """What a ``TrackLine`` row of ``geometry``'s line, ``margin_cm`` in, is computed from."""
    return racing_line.line_key(geometry, CarSpec(), margin_cm / 100)


def lap_against_line(seconds: float, line_seconds: float) -> str:
    """A lap against the line's, in words for a results table: "+1.25 s (118%)"."""
    return f"{seconds - line_seconds:+.2f} s ({seconds / line_seconds:.0%})"


def track_line_request(*, track: Track, direction: str, margin_cm: int, key: str) -> None:
    """Have a worker compute ``track``'s line (its row made or moved back to computing, the
    task sent once that is committed)."""
    fields = {"key": key, "message": "", "requested_at": timezone.now()}
    row, made = TrackLine.objects.get_or_create(
        track=track,
        direction=direction,
        margin_cm=margin_cm,
        defaults={**fields, "status": TrackLine.Status.COMPUTING},
    )
    if not made:
        lifecycle.TRACK_LINE.move(row, TrackLine.Status.COMPUTING, **fields)
    transaction.on_commit(lambda: queueing.enqueue(COMPUTE, row.pk), robust=True)


def track_lines_request_all(*, track: Track, geometry: simulator_tracks.Track) -> None:
    """Request the line of an added ``track`` (the simulator's ``geometry`` of it, already
    read: its route is not checked again) in each of its directions, without a margin."""
    for direction in track.direction_values:
        key = _key(geometry.with_direction(direction), 0)
        track_line_request(track=track, direction=direction, margin_cm=0, key=key)


def track_line_compute(*, line_id: int) -> None:
    """Compute the line of row ``line_id`` and store it (or why it failed); the worker's work."""
    row = TrackLine.objects.select_related("track").filter(pk=line_id).first()
    if row is None:
        log.info("Racing line %s is gone; nothing to compute.", line_id)
        return
    try:
        geometry = _geometry(row.track, row.direction)
        key = _key(geometry, row.margin_cm)
        line = racing_line.racing_line(geometry, margin=row.margin_cm / 100)
    except (simulator_tracks.TrackError, ValueError, ArithmeticError) as error:
        log.warning("The racing line of %s could not be computed: %s", row, error)
        lifecycle.TRACK_LINE.move(
            row.pk,
            TrackLine.Status.FAILED,
            message="The racing line could not be computed for this track's route.",
            computed_at=timezone.now(),
        )
        return
    array = np.column_stack([line.points, line.speeds]).astype(np.float32)
    lifecycle.TRACK_LINE.move(
        row.pk,
        TrackLine.Status.READY,
        key=key,
        message="",
        points=array.tobytes(),
        lap_time=line.lap_time,
        standing_lap_time=line.standing_lap_time,
        computed_at=timezone.now(),
    )


def reward_literal(shown: LineShown) -> str:
    """The line as a Python literal a reward function reads, in the track's own coordinates
    (``params["x"]``, ``params["y"]``), with what it is in comments. For DeepRacer's tracks they
    are DeepRacer's too: simapp reads the waypoints from the route file ``routes/WORLD_NAME.npy``
    (deepracer-simapp 01f5f01, bundle/markov/track_geom/track_data.py:194-204) and gives the
    reward function those waypoints and the car's position in the same world frame
    (bundle/markov/agent_ctrl/utils.py:112-118), as our route files and params do."""
    line = shown.line
    assert line is not None, "only a computed line is copied"
    direction = "clockwise" if shown.direction == "clockwise" else "counter-clockwise"
    margin = f", {shown.margin_cm} cm inside the borders" if shown.margin_cm else ""
    spacing = racing_line.SPACING * LITERAL_STRIDE
    rows = ",\n".join(
        f"    [{x:.4f}, {y:.4f}, {speed:.2f}]"
        for (x, y), speed in zip(
            line.points[::LITERAL_STRIDE], line.speeds[::LITERAL_STRIDE], strict=True
        )
    )
    return (
        f"# The racing line of {shown.track.name} driven {direction}{margin}, from Pitlane.\n"
        f"# [x, y, speed]: a point every {spacing:.1f} m from the start line; x and y in metres,\n"
        '# as params["x"] and params["y"] read them; the speed in m/s the line is driven at.\n'
        f"# A flying lap takes {line.lap_time:.2f} s; the first, from a standing start, "
        f"{line.standing_lap_time:.2f} s.\n"
        f"RACING_LINE = [\n{rows},\n]\n"
    )


def with_racing_line(source: str, shown: LineShown) -> str:
    """``source``, a reward function holding a racing line as ``reward_literal`` writes it (the
    reward editor's example), with ``shown``'s pasted over it, as a racer pastes the track page's
    copy."""
    start = source.index("# The racing line of ")
    end = source.index("\n]\n", start) + len("\n]\n")
    return source[:start] + reward_literal(shown) + source[end:]


# The speed palette (viridis), slowest first: the track page's map and the Analysis tab's
# (analysis.selectors.overview hands it to static/analysis/analysis.js).
SPEED_COLOURS = (
    "#440154", "#482878", "#3e4989", "#31688e", "#26828e",
    "#1f9e89", "#35b779", "#6ece58", "#b5de2b", "#fde725",
)  # fmt: skip
MAP_MARGIN = 0.3  # [m] around the track's borders on the map


def line_drawing(shown: LineShown) -> dict:
    """What the track page's map draws, in metres with y up (the SVG's y is flipped): the
    track's surface and borders, its start line, and the line in a path per speed band, with
    each band's speeds for the legend."""
    geometry = shown.geometry
    corners = np.vstack([geometry.inner, geometry.outer])
    low, high = corners.min(axis=0) - MAP_MARGIN, corners.max(axis=0) + MAP_MARGIN
    drawing = {
        "view_box": f"{low[0]:.3f} {-high[1]:.3f} {high[0] - low[0]:.3f} {high[1] - low[1]:.3f}",
        "surface": f"{_path(geometry.outer, closed=True)} {_path(geometry.inner, closed=True)}",
        "inner": _path(geometry.inner, closed=True),
        "outer": _path(geometry.outer, closed=True),
        "start": _path(np.array([geometry.inner[0], geometry.outer[0]])),
        "bands": [],
    }
    line = shown.line
    if line is None:
        return drawing
    slowest, fastest = float(line.speeds.min()), float(line.speeds.max())
    drawing.update(slowest=slowest, fastest=fastest)
    span = max(fastest - slowest, 1e-6)
    count = len(SPEED_COLOURS)
    # A segment's band is its speed's, its end's the next point (the line is closed).
    band = np.minimum(((line.speeds - slowest) / span * count).astype(int), count - 1)
    ends = np.roll(line.points, -1, axis=0)
    for number, colour in enumerate(SPEED_COLOURS):
        chosen = np.flatnonzero(band == number)
        if not len(chosen):
            continue
        segments = " ".join(
            f"M{a[0]:.3f} {-a[1]:.3f}L{b[0]:.3f} {-b[1]:.3f}"
            for a, b in zip(line.points[chosen], ends[chosen], strict=True)
        )
        drawing["bands"].append(
            {
                "colour": colour,
                "path": segments,
                "from": slowest + span * number / count,
                "to": slowest + span * (number + 1) / count,
            }
        )
    return drawing


def _path(points: np.ndarray, closed: bool = False) -> str:
    """An SVG path through ``points`` [m], y flipped."""
    moves = " ".join(f"{x:.3f} {-y:.3f}" for x, y in points)
    return f"M{moves}{'Z' if closed else ''}"
