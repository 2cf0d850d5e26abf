"""The track image the camera projects is drawn as simapp draws its tracks: its meshes' line
widths and dashes, its textures' colours as its camera shows them (simulator.texture cites each
file)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulator.env import DeepRacerEnv
from simulator.texture import (
    BORDER,
    CENTRE_LINE,
    REINVENT_2018,
    SIMAPP,
    SURFACE,
    SURROUNDINGS,
    WALL,
    render,
    style_for,
)
from simulator.tracks import load

PPM = 400  # [px/m]: a millimetre-fine image for measuring


@pytest.fixture(scope="module")
def ring(tmp_path_factory):
    """A 1 m wide ring round the origin, its centre line 2.5 m out."""
    theta = np.linspace(0, 2 * np.pi, 721)
    circle = np.column_stack([np.cos(theta), np.sin(theta)])
    path = tmp_path_factory.mktemp("ring") / "ring.npy"
    np.save(path, np.hstack([circle * 2.5, circle * 2.0, circle * 3.0]))
    track = load(str(path))
    return track, render(track, pixels_per_metre=PPM)


def level_at(texture, x: float, y: float) -> int:
    column, row = np.round(texture.to_pixels(np.array([[x, y]]))[0]).astype(int)
    return int(texture.image[row, column])


def test_each_border_is_a_76_mm_band_inside_the_tracks_edge(ring):
    # reInvent2019_track.dae and 2022_reinvent_champ_ccw.dae: ol/il quads 0.0762 m across, whose
    # outer vertices are the road's. Across the ring at 90° round (clear of the start line):
    _, texture = ring
    across = {
        round(r * 1000): level_at(texture, 0.0, r)
        for r in (1.995, 2.005, 2.070, 2.083, 2.917, 2.930, 2.995, 3.005)
    }
    assert across == {
        1995: SURROUNDINGS[0],
        2005: BORDER[0],
        2070: BORDER[0],
        2083: SURFACE[0],
        2917: SURFACE[0],
        2930: BORDER[0],
        2995: BORDER[0],
        3005: SURROUNDINGS[0],
    }


def test_the_centre_line_is_dashed_51_mm_on_and_51_mm_off_and_25_mm_wide(ring):
    # cl-verts: quads 0.0254 m wide and 0.0508 m long, one every 0.1016 m.
    track, texture = ring
    distances = np.arange(1.0, 3.0, 0.001)
    xs, ys, _ = track.point_at(distances)
    on = np.array([level_at(texture, x, y) == CENTRE_LINE[0] for x, y in zip(xs, ys, strict=True)])
    edges = np.flatnonzero(np.diff(on.astype(int)))  # each a start or an end of a dash
    starts = edges[on[edges + 1]]
    ends = edges[~on[edges + 1]]
    ends = ends[ends > starts[0]]
    lengths = ends[: len(starts) - 1] - starts[: len(ends)][: len(starts) - 1]
    assert np.median(np.diff(starts)) * 0.001 == pytest.approx(0.1016, abs=0.002)
    assert np.median(lengths) * 0.001 == pytest.approx(0.0508, abs=0.004)
    middle = track.point_at(float(distances[starts[3]] + 0.025))
    x, y, heading = middle
    side = (-math.sin(heading), math.cos(heading))
    width = [
        level_at(texture, x + side[0] * o, y + side[1] * o) == CENTRE_LINE[0]
        for o in np.arange(-0.03, 0.03, 0.001)
    ]
    assert sum(width) * 0.001 == pytest.approx(0.0254, abs=0.004)


@pytest.mark.parametrize(
    ("part", "seen_by_simapp"),
    # simapp's camera on re:Invent 2018 in deepracer-utils' sample frames (pictures/dr-demo-*.png,
    # rl_coach's luma): the road 45-58, the grass 130-140, the borders 199-225, the orange centre
    # line 136-141, the walls 14-24.
    [("surface", (45, 58)), ("surroundings", (130, 140)), ("border", (199, 225)),
     ("centre_line", (136, 141))],
)  # fmt: skip
def test_the_camera_sees_each_part_of_reinvent_2018_at_the_level_simapps_camera_does(
    part, seen_by_simapp
):
    low, high = seen_by_simapp
    assert low <= getattr(REINVENT_2018, part)[0] <= high
    assert 14 <= WALL[0] <= 24


def test_reinvent_2018_is_drawn_with_its_own_textures_and_the_others_with_the_common_ones():
    assert (
        DeepRacerEnv(track="reinvent_base")._cameras[0].texture.image.min()
        == (REINVENT_2018.surface[0])
    )
    assert style_for(load("Bowtie_track")) == SIMAPP
    assert style_for(load("reInvent2019_track")) == SIMAPP


def test_the_camera_sees_the_road_darker_than_the_grass_and_the_walls_above_the_horizon():
    observation, _ = DeepRacerEnv(track="reInvent2019_track", start=0.02).reset(seed=0)
    frame = observation["FRONT_FACING_CAMERA"][0]
    assert (frame[:26] == WALL[0]).all()
    assert np.median(frame[100:]) == pytest.approx(SURFACE[0], abs=3)
    assert SURFACE[0] < SURROUNDINGS[0] < CENTRE_LINE[0] < BORDER[0]
