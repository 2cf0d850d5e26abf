"""The racing line (``simulator.racing_line``): inside the borders, within the grip, drivable, and
stored for every built-in track in each of its directions."""

import numpy as np
import pytest

from simulator import tracks
from simulator.car import CarSpec
from simulator.controller import RacingLineDriver
from simulator.racing_line import Limits, line_key, racing_line, speed_profile, stored_line
from tests.simulator.conftest import CONTINUOUS, drive, make

SPEC = CarSpec()
BUILT_IN = [
    (name, direction) for name in tracks.names() for direction in tracks.entry(name)["directions"]
]


def built_in(name: str, direction: str):
    return tracks.load(name).with_direction(direction)


@pytest.mark.parametrize(("name", "direction"), BUILT_IN, ids=[f"{n}-{d}" for n, d in BUILT_IN])
def test_every_built_in_line_is_stored_current_inside_the_borders_and_within_the_grip(
    name, direction
):
    track = built_in(name, direction)
    line = stored_line(track)
    assert line is not None, f"stale or missing: python -m simulator.racing_line {name}"
    where = track.project_points(line.points)
    room = where.half_width - where.offset  # [m] from the car's middle to the border
    assert room.min() >= SPEC.width / 2 - 0.01, f"{room.min():.3f} m at {room.argmin()}"
    limits = Limits.of(SPEC)
    assert (line.speeds <= limits.top_speed + 1e-4).all()
    # The speed at each point turns the line's bend there within the grip asked for.
    lateral = line.speeds**2 * np.abs(line.curvature)
    assert lateral.max() <= limits.cornering * 1.001
    assert line.standing_lap_time > line.lap_time > 0


def test_a_line_stored_is_what_the_method_computes_and_a_new_car_makes_it_stale():
    track = built_in("rookie-loop", "counterclockwise")
    stored, computed = stored_line(track), racing_line(track)
    # The refinement stops where finite differences of 10 µm no longer gain, which depends on
    # the processor's floating-point paths: on another CPU (an AMD EPYC's against the one that
    # stored the lines) it stops in a neighbouring optimum, 0.1-0.2% apart and within 3 cm.
    assert stored.lap_time == pytest.approx(computed.lap_time, rel=0.005)
    assert np.abs(stored.points - computed.points).max() < 0.05
    slippery = CarSpec(friction=0.4)
    assert line_key(track, slippery, 0.0) != line_key(track, SPEC, 0.0)
    assert stored_line(track, slippery) is None
    assert racing_line(track, slippery).lap_time > computed.lap_time


def test_a_margin_keeps_the_line_further_in_and_costs_time():
    track = built_in("reInvent2019_track", "counterclockwise")
    line, wide = stored_line(track), racing_line(track, margin=0.1)
    where = track.project_points(wide.points)
    assert (where.half_width - where.offset).min() >= SPEC.width / 2 + 0.1 - 0.01
    assert wide.lap_time > line.lap_time


def test_the_profile_brakes_for_a_bend_and_accelerates_out_as_the_car_can():
    # A stadium: two straights, two half circles of 1 m radius.
    straight, radius = 6.0, 1.0
    along = np.arange(0, straight, 0.05)
    arc = np.linspace(0, np.pi, 64, endpoint=False)
    points = np.vstack(
        [
            np.column_stack([along, np.zeros_like(along)]),
            np.column_stack([straight + radius * np.sin(arc), radius - radius * np.cos(arc)]),
            np.column_stack([straight - along, np.full_like(along, 2 * radius)]),
            np.column_stack([-radius * np.sin(arc), radius + radius * np.cos(arc)]),
        ]
    )
    limits = Limits(top_speed=3.6, cornering=4.0, accelerating=5.0, braking=5.0)
    speeds, lap = speed_profile(points, limits)
    bend = np.sqrt(limits.cornering * radius)  # 2 m/s
    assert speeds[len(along) + 32] == pytest.approx(bend, rel=0.01)
    assert speeds.max() == pytest.approx(limits.top_speed)
    # From the bend to the top speed: (3.6² - 2²) / (2 * 5) = 0.896 m of straight.
    reached = np.argmax(speeds[: len(along)] >= limits.top_speed - 1e-6)
    assert along[reached] == pytest.approx(0.896, abs=0.06)
    assert lap < 2 * straight / bend + 2 * np.pi * radius / bend


# hairpin-alley counterclockwise: a hairpin's exit, where the centre-line driver's law ran wide
# and off the track (``python -m bench.bench_racing_line --all --directions`` drives all 122).
DRIVEN = [
    ("rookie-loop", "counterclockwise"),
    ("reInvent2019_track", "counterclockwise"),
    ("hairpin-alley", "counterclockwise"),
]


@pytest.mark.parametrize(("name", "direction"), DRIVEN, ids=[f"{n}-{d}" for n, d in DRIVEN])
def test_a_driver_that_follows_the_line_laps_clean_within_3_percent_of_its_time(name, direction):
    track = built_in(name, direction)
    line = stored_line(track)
    env = make(track=name, direction=direction, mode="evaluation", laps=2, action_space=CONTINUOUS)
    env.reset(seed=0)
    infos = drive(env, RacingLineDriver(env.unwrapped, line))
    assert infos[-1]["status"] == "lap_complete" and not infos[-1]["resets"]
    standing, flying = infos[-1]["lap_times"]
    assert standing == pytest.approx(line.standing_lap_time, rel=0.03)
    assert flying == pytest.approx(line.lap_time, rel=0.03)
