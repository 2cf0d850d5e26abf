"""Poses on a route file -> the reward params and trace fields DeepRacer would give there.

Each expected value is derived from reading DeepRacer's simulation code (aws-deepracer-community/
deepracer-simapp at 01f5f01; the rule's file and line is in the row's comment), not from running
Pitlane. The route is a stadium made here: a straight along y = -2 from x = 0 to 6 with waypoints
every 0.5 m (waypoint i at x = 0.5 i), a half circle, the straight back along y = 2 and a half
circle home; its points run counter-clockwise and the file repeats the first at the end.
"""

import math

import numpy as np
import pytest

from simulator.car import CarSpec, lidar_mount
from tests.simulator.conftest import make

WIDTH = 1.0668  # [m]
RADIUS = 2.0  # [m] of the half circles
SPEC = CarSpec()
# simapp: the reported point is 0.14 m ahead of base_link, which is nearly midway between the axles
# (agent_ctrl/constants.py:24, rollout_agent_ctrl.py:630-638); our car's origin is the rear axle.


def stadium(repeat: int | None = None) -> np.ndarray:
    straight = np.arange(0.0, 6.0, 0.5)
    arc = np.linspace(-math.pi / 2, math.pi / 2, 16, endpoint=False)
    centre = np.vstack(
        [
            np.column_stack([straight, np.full_like(straight, -RADIUS)]),
            np.column_stack([6.0 + RADIUS * np.cos(arc), RADIUS * np.sin(arc)]),
            np.column_stack([6.0 - straight, np.full_like(straight, RADIUS)]),
            np.column_stack([-RADIUS * np.cos(arc), -RADIUS * np.sin(arc)]),
        ]
    )
    closed = np.vstack([centre[-1:], centre, centre[:1]])
    tangent = (closed[2:] - closed[:-2]) / np.linalg.norm(closed[2:] - closed[:-2], axis=1)[:, None]
    left = np.column_stack([-tangent[:, 1], tangent[:, 0]])  # towards the inside
    route = np.hstack([centre, centre + left * WIDTH / 2, centre - left * WIDTH / 2])
    if repeat is not None:  # a waypoint written twice in a row, as some of DeepRacer's files do
        route = np.insert(route, repeat + 1, route[repeat], axis=0)
    return np.vstack([route, route[:1]])


@pytest.fixture
def route(tmp_path):
    def write(**kwargs) -> str:
        path = tmp_path / f"stadium-{len(list(tmp_path.iterdir()))}.npy"
        np.save(path, stadium(**kwargs))
        return str(path)

    return write


@pytest.fixture
def env(route):
    made = []

    def factory(**settings):
        made.append(make(track=route(repeat=settings.pop("repeat", None)), **settings))
        made[-1].reset(seed=0)
        return made[-1]

    yield factory
    for each in made:
        each.close()


def held_at(env, monkeypatch, x: float, y: float, yaw: float = 0.0, *, reported: bool = True):
    """Put the car where its reported point (or, with ``reported=False``, base_link, its model
    origin) is (x, y), hold it there, and take one step: that step's info."""
    ahead = SPEC.report_offset if reported else SPEC.base_link
    car = env.unwrapped.car
    car.place(x - ahead * math.cos(yaw), y - ahead * math.sin(yaw), yaw)
    monkeypatch.setattr(car, "step", lambda *args: 0.0)
    return env.step(2)[4]  # 0° at 0.5 m/s, going nowhere


def test_x_y_is_014_m_ahead_of_base_link(env, monkeypatch):
    # simapp rollout_agent_ctrl.py:630-638; the trace's X, Y is the same point (utils.py:117-120).
    info = held_at(env(), monkeypatch, 2.0, -2.0, reported=False)
    params, row = info["params"], info["trace"]
    assert (params["x"], params["y"]) == pytest.approx((2.14, -2.0))
    assert (params["x"], params["y"]) == (row.X, row.Y)


def test_exactly_on_waypoint_i_the_closest_waypoints_are_i_and_the_next(env, monkeypatch):
    # simapp track_geom/utils.py:140-147: bisect_right, so a point on waypoint 4 gives [4, 5].
    info = held_at(env(), monkeypatch, 2.0, -2.0)
    assert info["params"]["x"] == 2.0  # exactly on waypoint 4
    assert info["params"]["closest_waypoints"] == [4, 5]


def test_between_two_waypoints_the_trace_names_the_nearer_a_tie_going_behind(env, monkeypatch):
    # simapp agent_ctrl/utils.py:124-125: next if it is strictly nearer, else prev.
    racer = env()
    for x, params_pair, nearest in ((2.1, [4, 5], 4), (2.25, [4, 5], 4), (2.4, [4, 5], 5)):
        info = held_at(racer, monkeypatch, x, -2.0)
        assert info["params"]["closest_waypoints"] == params_pair
        assert info["trace"].closest_waypoint == nearest, x


def test_on_the_loops_last_segment_the_closing_point_is_ahead_not_waypoint_0(env, monkeypatch):
    # A LinearRing's normalised projection stays under 1.0, so next is N - 1 (the closing point):
    # simapp track_geom/track_data.py:47-48 with utils.py:140-147.
    racer = env()
    waypoints = racer.unwrapped.track.waypoints
    last = len(waypoints) - 1
    (x0, y0), (x1, y1) = waypoints[last - 1], waypoints[last]
    heading = math.atan2(y1 - y0, x1 - x0)
    info = held_at(racer, monkeypatch, (x0 + x1) / 2, (y0 + y1) / 2, heading)
    assert info["params"]["closest_waypoints"] == [last - 1, last]
    assert waypoints[last] == waypoints[0]


def test_a_repeated_waypoint_is_counted_once_as_the_sanitised_list_has_it(env, monkeypatch):
    # simapp track_geom/track_data.py:260-270 drops a row that repeats the one before, so the
    # indices after it are those of the list without it: the same as the route without a repeat.
    racer = env(repeat=2)
    assert len(racer.unwrapped.track.waypoints) == len(stadium())
    info = held_at(racer, monkeypatch, 2.0, -2.0)
    assert info["params"]["closest_waypoints"] == [4, 5]


def test_steps_is_a_float_and_the_first_reward_call_sees_two(route):
    # simapp rollout_agent_ctrl.py:180 (0.0), 643 (+1 per step), 779-780 (no reward call while
    # preparing), 1079 (each episode starts in prepare).
    seen = []
    racer = make(track=route(), reward_fn=lambda params: seen.append(params["steps"]) or 1.0)
    try:
        _, prepare = racer.reset(seed=0)
        assert prepare["params"] is None and prepare["trace"].steps == 1.0
        racer.step(2)
        racer.step(2)
    finally:
        racer.close()
    assert seen == [2.0, 3.0] and all(type(steps) is float for steps in seen)


def test_a_time_trial_has_every_object_key_at_deepracers_defaults(env, monkeypatch):
    # simapp agent_ctrl/constants.py:110-136; get_object_reward_params returns {} without objects.
    params = held_at(env(), monkeypatch, 2.0, -2.0)["params"]
    assert params["closest_objects"] == [0, 0]
    assert params["object_in_camera"] is False
    for key in (
        "objects_location",
        "objects_distance",
        "objects_distance_from_center",
        "objects_heading",
        "objects_left_of_center",
        "objects_speed",
    ):
        assert params[key] == [], key


def test_a_bot_cars_heading_is_in_radians_and_every_object_has_the_bot_speed(env, monkeypatch):
    # simapp track_data.py:385-394: the yaw from quaternion_to_euler (radians) and BOT_CAR_SPEED.
    racer = env(race_type="HEAD_TO_BOT", bots={"count": 1, "speed": 0.7})
    (bot,) = racer.unwrapped.traffic.actors
    top = racer.unwrapped.track.length - math.pi * RADIUS  # where the straight back ends
    bot.distance, bot.offset = top - 3.0, 0.0  # at x = 3 on the straight back, going -x
    bot.target_offset = 0.0
    racer.unwrapped.traffic._update_poses()
    racer.unwrapped._sync_actor_bodies()
    params = held_at(racer, monkeypatch, 2.0, -2.0)["params"]
    (heading,) = params["objects_heading"]
    assert abs(heading) == pytest.approx(math.pi)  # not 180
    assert params["objects_speed"] == [0.7]
    assert params["objects_location"] == [[pytest.approx(3.0, abs=0.05), pytest.approx(RADIUS)]]
    # The bot is behind the car along the line and ahead too: one object is both.
    assert params["closest_objects"] == [0, 0]


def test_object_in_camera_is_whether_the_next_object_is_in_view(env, monkeypatch):
    # simapp track_data.py:422-426 with the camera frustum (cameras/frustum.py).
    racer = env(race_type="OBJECT_AVOIDANCE", objects={"count": 1})
    _box_on_the_first_straight(racer)
    assert held_at(racer, monkeypatch, 2.0, -2.0)["params"]["object_in_camera"] is True
    looking_away = held_at(racer, monkeypatch, 2.0, -2.0, math.pi / 2)["params"]
    assert looking_away["object_in_camera"] is False


def _box_on_the_first_straight(racer) -> None:
    """Put the race's one box on the first straight, at x = 4, on the centre line."""
    (box,) = racer.unwrapped.traffic.actors
    box.distance, box.offset = 4.0, 0.0
    racer.unwrapped.traffic._update_poses()
    racer.unwrapped._sync_actor_bodies()


def test_object_in_camera_keeps_simapps_113_rad_with_the_wide_lens(env, monkeypatch):
    # frustum.py:43 hard-codes 1.13 rad whatever the camera: a box 50° off the wide lens's axis
    # is in its 120° picture but not in DeepRacer's param.
    racer = env(race_type="OBJECT_AVOIDANCE", objects={"count": 1}, camera_lens="wide")
    assert racer.unwrapped.config["camera_fov"] == 120.0
    _box_on_the_first_straight(racer)
    assert held_at(racer, monkeypatch, 2.0, -2.0)["params"]["object_in_camera"] is True
    turned = held_at(racer, monkeypatch, 2.0, -2.0, math.pi / 4)["params"]
    assert turned["object_in_camera"] is False


@pytest.mark.parametrize(("gap", "sectors"), [(0.4, [0, 0, 0, 1, 1, 0, 0, 0]), (0.6, [0] * 8)])
def test_sector_lidar_marks_a_sector_whose_nearest_return_is_under_half_a_metre(
    env, monkeypatch, gap, sectors
):
    # simapp: 64 rays over ±150° of the laser's heading in 8 groups of 8 from -150°, 1 when the
    # sector's minimum is under 0.5 m (environments/constants.py:27,29;
    # observation_sector_discretize_filter.py:53-71). The laser faces backwards
    # (deepracer_single_cam_lidar.urdf:537): the middle sectors look behind the car.
    racer = env(
        race_type="OBJECT_AVOIDANCE",
        objects={"count": 1},
        sensors=["FRONT_FACING_CAMERA", "SECTOR_LIDAR"],
    )
    (box,) = racer.unwrapped.traffic.actors
    box.distance, box.offset = 4.0, 0.0  # its far face at x = 4 + 0.25
    racer.unwrapped.traffic._update_poses()
    racer.unwrapped._sync_actor_bodies()
    lidar_x = 4.0 + box.length / 2 + gap  # the car drives away from it
    car = racer.unwrapped.car
    car.place(lidar_x - lidar_mount()[0], -2.0, 0.0)
    observation = racer.unwrapped._observe()
    assert observation["SECTOR_LIDAR"].tolist() == sectors
