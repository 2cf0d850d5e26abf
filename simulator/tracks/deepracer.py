"""Brings DeepRacer's tracks into ``data/deepracer/``: ``python -m simulator.tracks.deepracer``.

    python -m simulator.tracks.deepracer ROUTES_DIR TRACKS_JSON TRACK_UTILS_PY

ROUTES_DIR holds simapp's route files (deepracer-simapp bundle/routes/*.npy), TRACKS_JSON is
DeepRacer on AWS's console catalogue (source/libs/config/src/data/tracks.json) and
TRACK_UTILS_PY is deepracer-utils' deepracer/tracks/track_utils.py, whose ``track_meta`` names
the tracks and groups them by season in its comments ("# 2022 tracks", ...). The files' origins,
commits and licences are in ``data/deepracer/NOTICE``.

A console track is one track here, whatever its route files: the console passes its trackId as
WORLD_NAME and, for a track with both directions, TRACK_DIRECTION_CLOCKWISE (deepracer-on-aws
source/libs/lambda/src/workflow/utils/SimulationEnvironmentHelper.ts:53-56), which simapp turns
into WORLD_NAME + "_cw" or "_ccw" (simapp bundle/markov/boto/s3/files/yaml_file.py:228-246), so
each direction drives its own route file; a one-direction track drives the trackId's own file.
Every other route file (an eval variant, a textured copy, ...) is a track of its own, named as
``track_meta`` names it, driven either way as DeepRacer for Cloud's REVERSE_DIR allows (simapp
bundle/markov/track_geom/track_data.py:185). Lengths and widths are measured from the route files:
the console's ``width`` mixes centimetres and metres.
"""

from __future__ import annotations

import json
import re
import shutil
import sys
from pathlib import Path

import cv2

from simulator.texture import preview
from simulator.tracks import DEEPRACER_DIR, TrackError, _catalog, load

PREVIEW_WIDTH = 240  # [px] small: the catalogue's previews stay under a megabyte
CONSOLE_DIRECTIONS = {"COUNTER_CLOCKWISE": "counterclockwise", "CLOCKWISE": "clockwise"}
SUFFIXES = {"counterclockwise": "_ccw", "clockwise": "_cw"}
SEASON_COMMENT = re.compile(r"#\s*(\d{4})( and earlier)? tracks")
META_LINE = re.compile(r'track_meta\["([^"]+)"\]\s*=\s*"([^"]*)"')


def track_meta(source: str) -> dict[str, tuple[str, int]]:
    """WORLD_NAME -> (display name, season year) from track_utils.py's text: each name takes the
    year of the "# YYYY tracks" comment above it (2019 for "2019 and earlier")."""
    found, season = {}, None
    for line in source.splitlines():
        if match := SEASON_COMMENT.search(line):
            season = int(match.group(1))
        elif (match := META_LINE.search(line)) and season is not None:
            found[match.group(1)] = (match.group(2), season)
    return found


def difficulty(score: int) -> str:
    """The console's difficulty score (10 to 94) as our four words, in even quarters of 0-100."""
    return ("beginner", "intermediate", "advanced", "expert")[min(int(score) // 25, 3)]


def console_entry(track: dict, routes: dict, meta: dict) -> dict:
    """A console track: its directions, the route file each drives, and every route file that
    names it (WORLD_NAME -> the direction that file is driven)."""
    name = track["trackId"]
    directions = [CONSOLE_DIRECTIONS[d] for d in track["enabledDirections"]]
    default = CONSOLE_DIRECTIONS[track["defaultDirection"]]
    directions.sort(key=lambda d: d != default)
    if len(directions) > 1:
        driven = {d: name + SUFFIXES[d] for d in directions}
    else:
        driven = {directions[0]: name}
    missing = [world for world in driven.values() if world not in routes]
    if missing:
        raise SystemExit(f"{name}: the console drives {', '.join(missing)}, which simapp lacks.")
    worlds = {w: routes[w].direction for w in (name, name + "_ccw", name + "_cw") if w in routes}
    for direction, world in driven.items():
        if routes[world].direction != direction:
            raise SystemExit(f"{world} runs {routes[world].direction}, not {direction}.")
    return {
        "name": name,
        "display_name": track["name"],
        "description": track["description"],
        "difficulty": difficulty(track["difficulty"]),
        "directions": directions,
        "routes": driven,
        "world_names": worlds,
        "season": _season(meta, worlds, name),
        "console": True,
    }


def other_entry(world: str, route, meta: dict) -> dict:
    """A route file the console never listed: a track of its own, either way round."""
    other = "clockwise" if route.direction == "counterclockwise" else "counterclockwise"
    display = meta.get(world, (world, None))[0]
    return {
        "name": world, "display_name": display,
        "description": f"A route of DeepRacer's simulator (WORLD_NAME {world}) that the console "
        "did not list.",
        "difficulty": "intermediate", "directions": [route.direction, other],
        "routes": {route.direction: world}, "world_names": {world: route.direction},
        "season": _season(meta, {world: None}, world), "console": False,
    }  # fmt: skip


def _season(meta: dict, worlds: dict, name: str) -> int | None:
    for world in (name, *worlds):
        if world in meta:
            return meta[world][1]
    return None


def catalogue(routes_dir: Path, console: list[dict], meta: dict) -> tuple[list[dict], list[str]]:
    """The entries, and the route files left out (with why)."""
    routes, refused = {}, []
    for path in sorted(routes_dir.glob("*.npy")):
        try:
            routes[path.stem] = load(path)
        except TrackError as error:
            refused.append(f"{path.stem}: {error}")
    entries = [console_entry(track, routes, meta) for track in console]
    taken = {world for entry in entries for world in entry["world_names"]}
    entries += [
        other_entry(w, routes[w], meta) for w in sorted(routes, key=str.lower) if w not in taken
    ]
    for entry in entries:
        track = routes[entry["routes"][entry["directions"][0]]]
        entry["length_m"], entry["width_m"] = round(track.length, 2), round(track.width, 3)
    return entries, refused


def main(routes_dir: str, tracks_json: str, track_utils: str) -> None:
    console = json.loads(Path(tracks_json).read_text())["tracks"]
    meta = track_meta(Path(track_utils).read_text())
    entries, refused = catalogue(Path(routes_dir), console, meta)
    (DEEPRACER_DIR / "routes").mkdir(parents=True, exist_ok=True)
    for entry in entries:
        for world in entry["world_names"]:
            shutil.copyfile(
                Path(routes_dir) / f"{world}.npy", DEEPRACER_DIR / "routes" / f"{world}.npy"
            )
    with open(DEEPRACER_DIR / "catalog.json", "w") as file:
        json.dump(entries, file, indent=1)
        file.write("\n")
    _catalog.cache_clear()
    for entry in entries:
        shown = load(entry["name"]).with_direction(entry["directions"][0])
        cv2.imwrite(
            str(DEEPRACER_DIR / f"{entry['name']}.png"),
            preview(shown, width=PREVIEW_WIDTH),
            [cv2.IMWRITE_PNG_COMPRESSION, 9],
        )
    routes = sum(len(entry["world_names"]) for entry in entries)
    sys.stdout.write(
        f"{len(entries)} tracks from {routes} route files; left out: {'; '.join(refused)}\n"
    )


if __name__ == "__main__":
    main(*sys.argv[1:4])
