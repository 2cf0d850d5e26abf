"""What stands round each DeepRacer track, read from simapp's worlds and meshes:
``python -m simulator.tracks.surroundings BUNDLE_DIR``.

BUNDLE_DIR is deepracer-simapp's ``bundle/`` (its worlds/, models/ and meshes/). For every route
file in ``data/deepracer/routes`` the world of that name (bundle/worlds/<WORLD_NAME>.world)
includes its track model (``model://models/<name>``), whose SDF files name the COLLADA meshes
drawn; from their geometry this writes ``data/deepracer/surroundings.json``: the field the track
lies in, what edges it, and whether the world names a sky. What the camera makes of them is
``simulator.camera.Room``.

The edge, as the meshes have it:

- ``walls``: a wall mesh round the field (``wallmesh0`` in the 2019-2024 tracks' .dae,
  ``wallShape`` in reinvent_base_wall_field_only.dae, walls.dae round the re:Invent 2018
  carpets, the 2022 championship's background.dae 0.914 m high at its field's edge), its
  height the mesh's top: 1 m nearly everywhere.
- ``bank``: the first tracks (AWS_track, Bowtie_track, Oval_track, Virtual_May19_Train_track)
  have no walls: their grass runs on into ``bg_terrainShape``, a grass bank rising 1.2 m beyond
  the field to about 0.2 m (its top the 90th percentile of the heights in its outer 0.3 m).
- none: a field with nothing round it that we draw (the F1 and city worlds' barriers, buildings
  and backdrops are scenery we leave out), or no field mesh at all: the track's own margin.

Only numbers are taken from the meshes (each track's own files; Apache-2.0, NOTICE here).
"""

from __future__ import annotations

import json
import re
import sys
import xml.etree.ElementTree as ET
from collections import Counter
from pathlib import Path

import numpy as np

from simulator.tracks import DEEPRACER_DIR

COLLADA = "{http://www.collada.org/2005/11/COLLADASchema}"
BANK_BAND = 0.3  # [m] the bank's outer band whose heights give its top
FIT = 0.25  # [m] how near a background mesh's footprint must come to its field's to be walls
Rect = tuple[float, float, float, float]


def geometries(path: Path) -> list[tuple[str, np.ndarray]]:
    """Each geometry instance of a COLLADA file as (its id, its vertices in the file's frame:
    the visual scene's node matrices applied)."""
    root = ET.parse(path).getroot()  # noqa: S314 simapp's meshes, which a developer fetched
    meshes = {}
    for geometry in root.iter(COLLADA + "geometry"):
        source = geometry.find(f"{COLLADA}mesh/{COLLADA}source")
        if source is not None:
            values = source.find(COLLADA + "float_array").text.split()
            meshes[geometry.get("id")] = np.array(values, dtype=float).reshape(-1, 3)
    found = []

    def walk(node: ET.Element, transform: np.ndarray) -> None:
        matrix = node.find(COLLADA + "matrix")
        if matrix is not None:
            transform = transform @ np.array(matrix.text.split(), dtype=float).reshape(4, 4)
        for instance in node.findall(COLLADA + "instance_geometry"):
            vertices = meshes.get(instance.get("url").lstrip("#"))
            if vertices is not None:
                homogeneous = np.column_stack([vertices, np.ones(len(vertices))])
                found.append((instance.get("url").lstrip("#"), (homogeneous @ transform.T)[:, :3]))
        for child in node.findall(COLLADA + "node"):
            walk(child, transform)

    for scene in root.iter(COLLADA + "visual_scene"):
        for node in scene.findall(COLLADA + "node"):
            walk(node, np.eye(4))
    return found


def world_meshes(bundle: Path, world_name: str) -> tuple[bool, list[Path]] | None:
    """Whether ``world_name``'s world names a sky, and the visual meshes of its track models;
    None where simapp has no such world."""
    world = bundle / "worlds" / f"{world_name}.world"
    if not world.exists():
        return None
    text = world.read_text()
    paths = []
    for model in re.findall(r"model://models/([^<\s]+)", text):
        for sdf in sorted((bundle / "models" / model).glob("*.sdf")):
            for uri in re.findall(r"<uri>(?:model|file)://([^<]+\.dae)</uri>", sdf.read_text()):
                path = bundle / uri.removeprefix("bundle/")
                if "collision" not in path.name and path.exists() and path not in paths:
                    paths.append(path)
    return "<sky" in text, paths


def footprint(vertices: np.ndarray) -> Rect:
    low, high = vertices[:, :2].min(axis=0), vertices[:, :2].max(axis=0)
    return tuple(round(float(v), 3) for v in (*low, *high))


def encloses(outer: Rect, inner: Rect) -> bool:
    return (
        outer[0] <= inner[0]
        and outer[1] <= inner[1]
        and outer[2] >= inner[2]
        and (outer[3] >= inner[3])
    )


def area(rect: Rect) -> float:
    return (rect[2] - rect[0]) * (rect[3] - rect[1])


def near(a: Rect, b: Rect) -> bool:
    return max(abs(x - y) for x, y in zip(a, b, strict=True)) <= FIT


def surroundings(bundle: Path, world_name: str, road: Rect) -> dict | None:
    """The field round ``road`` (the route's extent) in ``world_name``, and its edge."""
    found = world_meshes(bundle, world_name)
    if found is None:
        return None
    sky, paths = found
    fields, walls, banks = [], [], []
    for path in paths:
        pieces = []
        for name, vertices in geometries(path):
            label = f"{path.stem} {name}".lower()
            if "bg_terrain" in name:
                banks.append(vertices)
            elif "field" in name.lower():
                fields.append(footprint(vertices))
            elif ("wall" in label and "building" not in label) or path.stem == "background":
                pieces.append(vertices)
        if pieces:  # a file's wall pieces together: walls.dae's four walls are one ring
            ring = np.concatenate(pieces)
            walls.append((footprint(ring), float(ring[:, 2].max()), path.stem == "background"))
    fields = [rect for rect in fields if encloses(rect, road)]
    rings = [
        (rect, height)
        for rect, height, backdrop in walls
        if encloses(rect, road)
        and height > 0.05
        and (not backdrop or any(near(rect, field) for field in fields))
    ]
    entry = {"sky": sky, "meshes": sorted(path.name for path in paths)}
    if rings:
        rect, height = min(rings, key=lambda ring: area(ring[0]))
        return {**entry, "field": list(rect), "edge": "walls", "height": round(height, 3)}
    for vertices in banks:
        rect = footprint(vertices)
        low, high = np.array(rect[:2]), np.array(rect[2:])
        inside = np.minimum(vertices[:, :2] - low, high - vertices[:, :2]).min(axis=1)
        top = float(np.percentile(vertices[inside <= BANK_BAND, 2], 90))
        return {**entry, "field": list(rect), "edge": "bank", "height": round(top, 3)}
    if fields:
        return {**entry, "field": list(min(fields, key=area)), "edge": None, "height": None}
    return {**entry, "field": None, "edge": None, "height": None}


def build(bundle: Path) -> dict:
    worlds = {}
    for route in sorted((DEEPRACER_DIR / "routes").glob("*.npy")):
        points = np.load(route).reshape(-1, 2)  # centre, inner and outer, (x, y) each
        road = (*points.min(axis=0).tolist(), *points.max(axis=0).tolist())
        if (found := surroundings(bundle, route.stem, road)) is not None:
            worlds[route.stem] = found
    return worlds


def main() -> None:
    if len(sys.argv) != 2:
        raise SystemExit(__doc__.split("\n\n")[0])
    worlds = build(Path(sys.argv[1]))
    text = json.dumps(worlds, indent=1, sort_keys=True)
    (DEEPRACER_DIR / "surroundings.json").write_text(text + "\n")
    edges = Counter(str(entry["edge"]) for entry in worlds.values())
    sys.stdout.write(f"{len(worlds)} worlds, by their field's edge: {dict(edges)}\n")


if __name__ == "__main__":
    main()
