"""What stands round the field a track lies in, and what shows above it: the room a camera
sees beyond the ground (``simulator.camera.PerspectiveView`` draws it)."""

from __future__ import annotations

from dataclasses import dataclass

from simulator.texture import BACKGROUND, WALL, WALL_HEIGHT, Style
from simulator.tracks import Track, surroundings


@dataclass(frozen=True)
class Room:
    """What stands round the field and what shows above it. simapp's tracks lie in a field
    edged by walls (1 m high in nearly every world: reinvent_base_wall_field_only.dae's wallShape
    0.91 m beyond the re:Invent 2018 track, the 2019-2024 tracks' wallmesh0 0.76 m beyond theirs)
    or, in the first tracks, by a grass bank about 0.2 m high (bg_terrainShape); above the edge
    the camera sees the world's background: SDF's default 0.7 gray (sdformat's scene.sdf), 178
    in the camera's gray, which deepracer-utils' frame dr-demo-2.png shows above reinvent_base's
    walls. Worlds that name a <sky/> (all but four) get the same background: Gazebo's sky is not
    rendered here. ``simulator.tracks.surroundings`` reads each world's field and edge from its
    meshes; ``room_for`` turns them into a Room."""

    height: float | None = WALL_HEIGHT  # [m] of the field's edge; None: nothing round the field
    background: int | tuple[int, int, int] = BACKGROUND[0]  # gray level, or BGR colour
    edge: int | tuple[int, int, int] = WALL[0]  # the walls' (or the bank's) shade
    field: tuple[float, float, float, float] | None = None  # [m] x0, y0, x1, y1; None: the
    # track image's extent

    @property
    def sky(self) -> int | tuple[int, int, int]:
        """What fills the picture above the horizon before the background over the edge."""
        return self.background if self.height is None else self.edge


def room_for(track: Track, style: Style) -> Room:
    """The room round ``track`` as its DeepRacer world has it (``simulator.tracks.surroundings``),
    or, for Pitlane's own tracks, walls 1 m high round the track image's margin."""
    found = surroundings(track.world_name or track.name)
    if found is None:
        return Room()
    if found["edge"] is None:
        return Room(height=None, field=found["field"] and tuple(found["field"]))
    edge = style.surroundings[0] if found["edge"] == "bank" else WALL[0]
    return Room(found["height"], edge=edge, field=tuple(found["field"]))
