"""Each DeepRacer world's field and what edges it, as simapp's meshes have them
(simulator.tracks.surroundings), and what the camera makes of them (simulator.camera.Room)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from simulator.env import DeepRacerEnv
from simulator.room import Room, room_for
from simulator.texture import SIMAPP, WALL, style_for
from simulator.tracks import DEEPRACER_DIR, load
from simulator.tracks.surroundings import surroundings

# A COLLADA node's matrix as simapp's Maya exports write it: inches, y up, turned to z up.
INCHES_Y_UP = np.array([[0.0254, 0, 0, 0], [0, 0, -0.0254, 0], [0, 0.0254, 0, 0], [0, 0, 0, 1]])


def collada(meshes: dict[str, np.ndarray], matrix: np.ndarray) -> str:
    """A COLLADA file holding ``meshes`` (id -> vertices), each placed by ``matrix``."""
    geometries = "".join(
        f'<geometry id="{name}"><mesh><source id="{name}-positions"><float_array count='
        f'"{vertices.size}">{" ".join(map(str, vertices.ravel()))}</float_array></source>'
        "</mesh></geometry>"
        for name, vertices in meshes.items()
    )
    values = " ".join(map(str, matrix.ravel()))
    nodes = "".join(
        f'<node id="{name}-node"><matrix>{values}</matrix><instance_geometry url="#{name}"/></node>'
        for name in meshes
    )
    return (
        '<?xml version="1.0"?><COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema">'
        f"<library_geometries>{geometries}</library_geometries><library_visual_scenes>"
        f'<visual_scene id="Scene">{nodes}</visual_scene></library_visual_scenes></COLLADA>'
    )


def box(low: tuple[float, float, float], high: tuple[float, float, float]) -> np.ndarray:
    return np.array(
        [(x, y, z) for x in (low[0], high[0]) for y in (low[1], high[1]) for z in (low[2], high[2])]
    )


def inches_y_up(points: np.ndarray) -> np.ndarray:
    """World (x, y, up) [m] as such a file holds them: INCHES_Y_UP takes them back."""
    return np.column_stack([points[:, 0], points[:, 2], -points[:, 1]]) / 0.0254


def a_world(bundle, name: str, meshes: dict[str, np.ndarray], matrix=None, sky=True):
    """simapp's layout: worlds/NAME.world includes models/NAME, whose SDF names the mesh."""
    (bundle / "worlds").mkdir(exist_ok=True)
    scene = "<sky/>" if sky else ""
    (bundle / "worlds" / f"{name}.world").write_text(
        f"<sdf><world><scene>{scene}</scene><include><uri>model://models/{name}</uri></include>"
        "</world></sdf>"
    )
    (bundle / "models" / name).mkdir(parents=True)
    (bundle / "models" / name / f"{name}_model.sdf").write_text(
        f"<sdf><model><link><visual><geometry><mesh><uri>model://meshes/{name}/{name}.dae</uri>"
        f"</mesh></geometry></visual><collision><geometry><mesh><uri>model://meshes/{name}/"
        f"{name}_collision.dae</uri></mesh></geometry></collision></link></model></sdf>"
    )
    (bundle / "meshes" / name).mkdir(parents=True)
    placed = np.eye(4) if matrix is None else matrix
    (bundle / "meshes" / name / f"{name}.dae").write_text(collada(meshes, placed))


def test_the_builder_reads_walls_a_grass_bank_or_nothing_round_the_field(tmp_path):
    road = (1.0, 1.0, 7.0, 5.0)
    a_world(
        tmp_path,
        "walled",
        {
            "roadmesh0": box((1, 1, 0), (7, 5, 0)),
            "fieldmesh0": box((0.24, 0.24, 0), (7.76, 5.76, 0)),
            "wallmesh0": box((0.24, 0.24, 0), (7.76, 5.76, 1)),
        },
        sky=False,
    )
    # a bank, in inches with y up: at the field's edge, rising to 0.2 m in its outer 0.3 m
    bank = [(x, y, 0.0) for x in (-1.016, 7.62) for y in (-1.016, 5.842)]
    bank += [(-1.0 + 0.1 * i, 2.0, 0.2) for i in range(3)] + [(3.0, 2.0, 0.0)]
    a_world(
        tmp_path,
        "banked",
        {
            "fieldShape-mesh": inches_y_up(box((0, 0, 0), (7.4, 5.2, 0))),
            "bg_terrainShape-mesh": inches_y_up(np.array(bank)),
        },
        matrix=INCHES_Y_UP,
    )
    a_world(tmp_path, "open", {"fieldShape": box((-9, -9, 0), (17, 15, 0))})

    walled = surroundings(tmp_path, "walled", road)
    assert walled["edge"] == "walls" and walled["height"] == 1.0 and walled["sky"] is False
    assert walled["field"] == [0.24, 0.24, 7.76, 5.76]
    banked = surroundings(tmp_path, "banked", road)
    assert banked["edge"] == "bank" and banked["sky"] is True
    assert banked["field"] == pytest.approx([-1.016, -1.016, 7.62, 5.842])
    assert banked["height"] == pytest.approx(0.2, abs=1e-3)
    assert surroundings(tmp_path, "open", road)["edge"] is None
    assert surroundings(tmp_path, "elsewhere", road) is None


def test_every_route_file_has_its_worlds_field_round_it():
    worlds = json.loads((DEEPRACER_DIR / "surroundings.json").read_text())
    routes = sorted(path.stem for path in (DEEPRACER_DIR / "routes").glob("*.npy"))
    assert sorted(worlds) == routes
    for name, world in worlds.items():
        assert world["edge"] in ("walls", "bank", None), name
        if world["field"] is not None:
            points = np.load(DEEPRACER_DIR / "routes" / f"{name}.npy").reshape(-1, 2)
            low, high = np.array(world["field"][:2]), np.array(world["field"][2:])
            assert (points.min(axis=0) >= low).all() and (points.max(axis=0) <= high).all(), name


def test_the_camera_stands_each_track_in_its_worlds_room():
    # reinvent_base_wall_field_only.dae's field and 1 m walls, no sky in reinvent_base.world
    assert room_for(load("reinvent_base"), style_for(load("reinvent_base"))) == Room(
        1.0, 178, WALL[0], (-0.587, -0.613, 8.575, 5.795)
    )
    # the 2019 track's _ccw route file is centred: its wallmesh0 0.76 m beyond its road
    room = room_for(load("reInvent2019_track"), SIMAPP)
    assert room.height == 1.0 and room.field == pytest.approx((-5.314, -4.279, 5.314, 4.278))
    # Bowtie_track.dae: no walls, its grass bank (bg_terrainShape) about 0.19 m high
    bowtie = room_for(load("Bowtie_track"), SIMAPP)
    assert bowtie.edge == SIMAPP.surroundings[0] and bowtie.height == pytest.approx(0.19)
    assert room_for(load("Spain_track"), SIMAPP).height is None  # its barriers are not drawn
    assert room_for(load("rookie-loop"), SIMAPP) == Room()  # Pitlane's: 1 m walls at its margin


def test_over_bowties_bank_the_camera_sees_the_background_down_to_the_horizon():
    frame = DeepRacerEnv(track="Bowtie_track", start=0.0).reset(seed=0)[0]["FRONT_FACING_CAMERA"]
    frame = frame[0]
    assert (frame[:24] == 178).all()  # the horizon is row 26.2; the bank tops it by a row or two
    assert not (frame == WALL[0]).any()
    walled = DeepRacerEnv(track="reinvent_base", start=0.0).reset(seed=0)[0]
    assert (walled["FRONT_FACING_CAMERA"][0][:26] == WALL[0]).sum() > 160 * 10
