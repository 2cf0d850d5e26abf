"""What the analysis pages read: a source's summaries combined over the iterations and outcomes a
racer picks, single episodes read back from their trace, and the track's racing line with a
lap's sectors against it (``analysis.sectors``)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from datetime import timedelta

import numpy as np
from django.db.models import Max
from django.utils import timezone

from analysis import sectors, summaries, traces
from analysis.models import Rescoring
from analysis.records import Source
from common import turns
from simulator import params as reward_params
from simulator import tracks as simulator_tracks
from simulator.car import CarSpec
from simulator.racing_line import Limits
from training import track_lines
from training.models import TrackLine

EPISODE_COLUMNS = (
    "iteration",
    "episode",
    "start",
    "steps",
    "progress",
    "seconds",
    "outcome",
    "reward",
)
MAP_POINTS = 60_000  # the most steps one map draws: evenly spread over what was picked
ROUND = 3  # decimals of a metre sent to the browser: a millimetre
LINE_STRIDE = 2  # every second point of the racing line (0.2 m apart) on the map
LINE_COMPUTING = "The racing line is being computed… Reload the page in a minute to see it."
LINE_FAILED = "The racing line could not be computed for this track."
NOT_A_LAP = "This episode did not complete a lap: only a lap is compared with the racing line."
ACCELERATING = Limits.of(CarSpec()).accelerating  # [m/s²] the line's car's
# [s] how long a racer's last re-scoring's start counts against them: one who asks again within
# it waits behind a racer who has not had one since (common.turns).
SERVED_MEMORY = 3600


@dataclass(frozen=True)
class Choice:
    """The iterations (``first``..``last``) and episode outcomes a racer picked."""

    first: int
    last: int
    outcomes: tuple[str, ...]

    @classmethod
    def parse(cls, query, *, iterations: list[int]) -> Choice:
        """From the page's query string; what is missing or wrong falls back to everything."""
        low, high = (min(iterations), max(iterations)) if iterations else (0, 0)
        first, last = _whole(query.get("first"), low), _whole(query.get("last"), high)
        first, last = sorted((min(max(first, low), high), min(max(last, low), high)))
        picked = [name for name in query.get("outcomes", "").split(",") if name in traces.OUTCOMES]
        return cls(first, last, tuple(picked) or traces.OUTCOMES)


def _whole(text: str | None, default: int) -> int:
    try:
        return int(text) if text is not None else default
    except ValueError:
        return default


def overview(source: Source) -> dict:
    """What the page needs before any choice: the track, the action space, the iterations and
    each one's figures (for the per-iteration chart), and the labels."""
    track = source.track
    rows = source.summaries().order_by("iteration").values_list("iteration", "episodes", "steps")
    iterations = [
        {"iteration": iteration, "steps": steps, **summaries.iteration_figures(episodes)}
        for iteration, episodes, steps in rows
    ]
    return {
        "track": {
            "name": track.display_name,
            "centre": np.round(track.centre, ROUND).tolist(),
            "inner": np.round(track.inner, ROUND).tolist(),
            "outer": np.round(track.outer, ROUND).tolist(),
            "direction": track.direction,
        },
        "actions": _action_labels(source),
        "continuous": source.actions is None,
        "iterations": iterations,
        "evaluation": source.evaluation is not None,
        "outcomes": [[name, traces.OUTCOME_LABELS[name]] for name in traces.OUTCOMES],
        "sections": summaries.SECTIONS,
        "steer_bins": _centres(summaries.STEER_EDGES),
        "speed_bins": _centres(summaries.SPEED_EDGES),
        "point_columns": [*summaries.POINT_COLUMNS, "iteration"],
        "racing_line": _line_drawn(racing_line(source)),
        "speed_colours": list(track_lines.SPEED_COLOURS),
    }


def racing_line(source: Source) -> track_lines.LineShown | None:
    """The racing line of the track ``source`` drove, its way, without a margin (requested
    from a worker where there is none yet); None where the track's file cannot be read."""
    where = source.evaluation or source.model  # an evaluation drives its own track, its way
    try:
        return track_lines.track_line(track=where.track, direction=where.direction, margin_cm=0)
    except simulator_tracks.TrackError:
        return None


def _line_drawn(shown: track_lines.LineShown | None) -> dict:
    """The line as the map draws it, [x, y, speed] rows, and its laps; or why there is none."""
    if shown is None or shown.line is None:
        status = shown.status if shown is not None else TrackLine.Status.FAILED
        if status == TrackLine.Status.COMPUTING:
            return {"status": status, "message": LINE_COMPUTING}
        return {"status": status, "message": (shown and shown.message) or LINE_FAILED}
    line = shown.line
    rows = np.column_stack([line.points, line.speeds])[::LINE_STRIDE]
    return {
        "status": shown.status,
        "message": "",
        "points": np.round(rows, ROUND).tolist(),
        "lap_time": round(line.lap_time, ROUND),
        "standing_lap_time": round(line.standing_lap_time, ROUND),
    }


def _centres(edges: np.ndarray) -> list[float]:
    return np.round((edges[:-1] + edges[1:]) / 2, 3).tolist()


def _action_labels(source: Source) -> list[str]:
    if source.actions is None:
        return []
    return [
        f"{index}: {float(a.get('steering_angle', 0)):g}°, {float(a.get('speed', 0)):g} m/s"
        for index, a in enumerate(source.model.action_space)
    ]


def picked(source: Source, choice: Choice) -> dict:
    """The episodes, off-track marks and action counts of what ``choice`` picked, and its
    fastest lap."""
    rows = (
        source.summaries()
        .filter(iteration__range=(choice.first, choice.last))
        .order_by("iteration")
        .values_list("iteration", "episodes", "marks", "actions")
    )
    codes = set(summaries.outcome_codes(list(choice.outcomes)))
    episodes, marks, actions = [], [], []
    for iteration, their_episodes, their_marks, their_actions in rows:
        episodes += [[iteration, *e] for e in their_episodes if e[5] in codes]
        marks += [[*m, iteration] for m in their_marks if m[2] in codes]
        actions.append(bytes(their_actions))
    laps = [e for e in episodes if e[6] == 0]  # [iteration, number, ..., outcome at 6]
    fastest = min(laps, key=lambda e: e[5]) if laps else None
    return {
        "first": choice.first,
        "last": choice.last,
        "outcomes": list(choice.outcomes),
        "episode_columns": EPISODE_COLUMNS,
        "episodes": episodes,
        "marks": marks,
        "actions": summaries.combine_actions(actions, list(choice.outcomes)),
        "fastest": fastest[:2] if fastest else None,
    }


def points(source: Source, choice: Choice, rescoring: Rescoring | None = None) -> bytes:
    """The map's points for ``choice``: float32 columns (``overview``'s ``point_columns``, then
    the re-scored reward when ``rescoring`` is given), one after another, little-endian."""
    rows = list(
        source.summaries()
        .filter(iteration__range=(choice.first, choice.last))
        .order_by("iteration")
        .values_list("iteration", "points")
    )
    extra = rescored_points(rescoring, [(i, bytes(p)) for i, p in rows]) if rescoring else None
    combined = summaries.combine_points(
        [(i, bytes(p)) for i, p in rows], list(choice.outcomes), MAP_POINTS, extra=extra
    )
    return combined.astype("<f4").tobytes()


def rescored_points(rescoring: Rescoring, rows: list[tuple[int, bytes]]) -> dict[int, np.ndarray]:
    """The re-scored reward of each summary point of ``rows`` that ``rescoring`` scored."""
    new = np.frombuffer(bytes(rescoring.points), dtype=np.float32)
    offsets, at = {}, 0
    for iteration in sorted(int(i) for i in rescoring.point_counts):  # as the runner wrote them
        offsets[iteration] = at
        at += rescoring.point_counts[str(iteration)]
    found = {}
    for iteration, data in rows:
        count = summaries.points_array(data).shape[1]
        start = offsets.get(iteration)
        if start is not None and rescoring.point_counts.get(str(iteration)) == count:
            found[iteration] = new[start : start + count]
    return found


def episode(source: Source, iteration: int, number: int) -> dict | None:
    """One episode's steps, with the reward params it was given at each (rebuilt from the trace:
    ``simulator.params.replayed``); None when it is not in the trace."""
    steps = source.read(iteration)
    found = [e for e in steps.episodes() if e.number == number]
    if not found:
        return None
    (chosen,) = found[:1]
    rows = slice(chosen.first, chosen.last + 1)
    track = source.track
    recorded = steps.recorded(rows)
    shown = (
        "x",
        "y",
        "heading",
        "speed",
        "steering_angle",
        "progress",
        "steps",
        "distance_from_center",
        "is_left_of_center",
        "track_width",
        "closest_waypoints",
        "all_wheels_on_track",
        "is_offtrack",
        "is_crashed",
    )
    params = [{name: p[name] for name in shown} for p in reward_params.replayed(track, recorded)]
    table, note = lap_sectors(source, steps, chosen)
    return {
        "iteration": iteration,
        "episode": number,
        "outcome": chosen.outcome,
        "status": chosen.status,
        "seconds": round(chosen.seconds, 3),
        "reward": round(chosen.reward, 4),
        "path": np.round(np.column_stack([steps.x[rows], steps.y[rows]]), ROUND).tolist(),
        "rewards": np.round(steps.reward[rows], 4).tolist(),
        "actions": steps.action[rows].tolist(),
        "statuses": steps.status[rows].tolist(),
        "params": params,
        "sectors": table,
        "sectors_note": note,
    }


def lap_sectors(
    source: Source, steps: traces.Steps, chosen: traces.Episode
) -> tuple[dict | None, str]:
    """``chosen``'s lap against the racing line, sector by sector (``analysis.sectors``), with
    ``standing``: whether the line's starts from rest, as the episode did; or None and why not,
    in words."""
    if chosen.status != "lap_complete" or chosen.last <= chosen.first:
        return None, NOT_A_LAP
    shown = racing_line(source)
    if shown is None or shown.line is None:
        return None, _line_drawn(shown)["message"]
    track, first, rows = source.track, chosen.first, slice(chosen.first, chosen.last + 1)
    start = track.project_points([steps.x[first], steps.y[first]]).distance[0] / track.length
    standing = bool(steps.status[first] == "prepare")  # the prepare row: the car held at rest
    line = sectors.line_lap(
        shown.line, track, start=start, standing=standing, accelerating=ACCELERATING
    )
    lap = sectors.recorded_lap(
        progress=steps.progress[rows], tstamp=steps.tstamp[rows], x=steps.x[rows], y=steps.y[rows]
    )
    return {**sectors.sector_table(line, lap, track), "standing": standing}, ""


def rescorings_in_turn() -> list[int]:
    """The queued re-scorings' ids in the order the workers will take them up: racers take
    turns (``common.turns``, as the reward checkers do), each racer's own first come first."""
    queued = Rescoring.objects.filter(status=Rescoring.Status.QUEUED).order_by("created_at", "pk")
    queues: dict[int, list[int]] = {}
    came: dict[int, float] = {}
    for pk, owner, created in queued.values_list("pk", "owner_id", "created_at"):
        queues.setdefault(owner, []).append(pk)
        came.setdefault(owner, created.timestamp())
    if not queues:
        return []
    theirs = Rescoring.objects.filter(owner_id__in=queues)
    running = Counter(
        theirs.filter(status=Rescoring.Status.RUNNING).values_list("owner_id", flat=True)
    )
    since = timezone.now() - timedelta(seconds=SERVED_MEMORY)
    served = {
        owner: started.timestamp()
        for owner, started in theirs.filter(started_at__gte=since)
        .values("owner_id")
        .annotate(last=Max("started_at"))
        .values_list("owner_id", "last")
    }
    return turns.in_turn(queues, running=running, served=served, came=came)


def rescoring_place(rescoring: Rescoring) -> int | None:
    """How many re-scorings, of every racer, a worker takes up before ``rescoring``, if it
    waits (0: it is next); None once it runs or has ended."""
    if rescoring.status != Rescoring.Status.QUEUED:
        return None
    order = rescorings_in_turn()
    return order.index(rescoring.pk) if rescoring.pk in order else None
