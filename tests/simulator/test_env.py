import itertools
import math

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from simulator import tracks
from simulator.car import GRAVITY
from simulator.config import ConfigError
from simulator.controller import CentreLineDriver
from simulator.rewards import RewardError
from simulator.tracks import TrackError
from tests.simulator.conftest import CONTINUOUS, drive

REWARD_KEYS = {
    "all_wheels_on_track",
    "x",
    "y",
    "heading",
    "distance_from_center",
    "is_left_of_center",
    "is_offtrack",
    "is_crashed",
    "is_reversed",
    "progress",
    "steps",
    "speed",
    "steering_angle",
    "track_width",
    "track_length",
    "waypoints",
    "closest_waypoints",
    "projection_distance",
    "sim_time",
}
OBJECT_KEYS = {
    "closest_objects",
    "objects_location",
    "objects_distance",
    "objects_distance_from_center",
    "objects_heading",
    "objects_left_of_center",
    "objects_speed",
    "object_in_camera",
}


@pytest.mark.parametrize(
    "settings",
    [
        {},
        {"sensors": ["STEREO_CAMERAS", "LIDAR"], "race_type": "HEAD_TO_BOT"},
        {"sensors": ["FRONT_FACING_CAMERA", "SECTOR_LIDAR"], "action_space": CONTINUOUS,
         "race_type": "OBJECT_AVOIDANCE", "objects": {"count": 2, "randomize": True}},
    ],
    ids=["camera", "stereo-lidar-bots", "continuous-sector-boxes"],
)  # fmt: skip
def test_the_environment_passes_gymnasiums_checks(environments, settings):
    env = environments(**settings)
    check_env(env.unwrapped, skip_render_check=True)


def test_the_same_seed_gives_the_same_episode(environments):
    settings = {
        "track": "s-bend",
        "race_type": "HEAD_TO_BOT",
        "bots": {"count": 2, "speed": 0.8, "lane_changes": True},
        "sensors": ["FRONT_FACING_CAMERA", "LIDAR"],
    }
    runs = []
    for _ in range(2):
        env = environments(**settings)
        observation, _ = env.reset(seed=42)
        rng = np.random.default_rng(7)
        frames, rows = [observation["FRONT_FACING_CAMERA"]], []
        for _ in range(120):
            observation, reward, terminated, truncated, info = env.step(rng.integers(10))
            frames.append(observation["FRONT_FACING_CAMERA"])
            rows.append(
                (reward, info["status"], info["params"]["objects_location"], info["trace"][:14])
            )
            if terminated or truncated:
                break
        runs.append((np.stack(frames), rows))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    assert runs[0][1] == runs[1][1]


def test_different_seeds_place_random_boxes_differently(environments):
    env = environments(race_type="OBJECT_AVOIDANCE", objects={"count": 3, "randomize": True})
    env.reset(seed=1)
    first = [a.distance for a in env.unwrapped.traffic.actors]
    env.reset(seed=2)
    assert first != [a.distance for a in env.unwrapped.traffic.actors]


# Pitlane's tracks both ways, and six of DeepRacer's route files: the shortest and the longest,
# a clockwise-only one, one with a file for each way, a textured copy and the newest.
DEEPRACER_LAPS = [
    ("reInvent2019_wide", "clockwise"), ("penbay_pro", "clockwise"), ("Albert", "clockwise"),
    ("2022_summit_speedway", "counterclockwise"), ("reinvent_carpet", "clockwise"),
    ("2024_reinvent_champ", "counterclockwise"),
]  # fmt: skip
LAPS = [
    (name, direction)
    for name in tracks.names(origin="pitlane")
    for direction in tracks.load(name).directions
] + DEEPRACER_LAPS


@pytest.mark.slow
@pytest.mark.parametrize(("name", "direction"), LAPS, ids=[f"{n}-{d}" for n, d in LAPS])
def test_the_scripted_driver_laps_every_track_in_the_time_its_speed_predicts(
    environments, name, direction
):
    env = environments(
        track=name, direction=direction, mode="evaluation", laps=1, action_space=CONTINUOUS
    )
    env.reset(seed=0)
    speed = 1.5
    infos = drive(env, CentreLineDriver(env.unwrapped, speed=speed))
    assert infos[-1]["status"] == "lap_complete"
    assert infos[-1]["resets"] == 0
    (lap,) = infos[-1]["lap_times"]
    # The driver follows the centre line at the speed the wheels are driven at, after a start at
    # the acceleration the grip allows (4WD: mu * g), which loses half the time it takes.
    spec = env.unwrapped.car.spec
    rolling = spec.wheel_target(speed)
    expected = env.unwrapped.track.length / rolling + rolling / (2 * spec.friction * GRAVITY)
    assert lap == pytest.approx(expected, rel=0.03)


def test_progress_rises_then_wraps_at_the_start_line(environments):
    env = environments(track="pitlane-oval", mode="evaluation", laps=2, action_space=CONTINUOUS)
    env.reset(seed=0)
    infos = drive(env)
    progress = [info["progress"] for info in infos]
    wrap = next(i for i, info in enumerate(infos) if info["lap"] == 2)
    assert infos[wrap - 1]["status"] == "lap_complete"
    assert progress[wrap - 1] == 100.0
    assert progress[wrap] < 2.0
    for lap in (progress[:wrap], progress[wrap:]):
        assert all(b >= a for a, b in itertools.pairwise(lap))
    assert infos[-1]["status"] == "lap_complete"
    assert len(infos[-1]["lap_times"]) == 2


class Straight:
    """Drives straight on at 1 m/s (action 7 of the default action space)."""

    def act(self) -> int:
        return 7


def head_for_the_border(env) -> Straight:
    """Turn the car 60° to the left of the track, to drive straight off it."""
    car = env.unwrapped.car
    car.place(car.x, car.y, car.yaw + math.radians(60))
    return Straight()


def test_off_track_when_all_four_wheels_leave(environments):
    env = environments(track="pitlane-oval")
    env.reset(seed=0)
    infos = drive(env, head_for_the_border(env))
    car, track = env.unwrapped.car, env.unwrapped.track
    assert infos[-1]["status"] == "off_track"
    assert not any(track.contains(wheel) for wheel in car.wheels())
    assert infos[-1]["params"]["is_offtrack"] is True
    assert infos[-2]["status"] == "in_progress"
    assert not infos[-2]["params"]["all_wheels_on_track"]  # some wheels left first


def test_crashed_on_a_box(environments):
    env = environments(track="pitlane-oval", race_type="OBJECT_AVOIDANCE", objects={"count": 1})
    env.reset(seed=0)
    car = env.unwrapped
    (box,) = car.traffic.actors
    x, y, heading = car.track.point_at(box.distance - 0.9, box.offset)
    car.car.place(float(x), float(y), float(heading))
    infos = drive(env, Straight())
    assert infos[-1]["status"] == "crashed"
    assert infos[-1]["params"]["is_crashed"] is True
    assert infos[-1]["trace"].obstacle_crash_counter == 0  # counted in evaluation only


def test_reversed_when_driving_the_wrong_way(environments):
    env = environments(track="pitlane-oval")
    env.reset(seed=0)
    car = env.unwrapped.car
    car.place(car.x, car.y, car.yaw + math.pi)
    infos = drive(env, type("Straight", (), {"act": lambda self: 2})())  # 0° at 0.5 m/s
    assert infos[-1]["status"] == "reversed"
    assert len(infos) == 15


def test_immobilized_when_stopped(environments, monkeypatch):
    env = environments(track="pitlane-oval")
    env.reset(seed=0)
    monkeypatch.setattr(env.unwrapped.car, "step", lambda *args: 0.0)  # held in place
    infos = drive(env, type("Any", (), {"act": lambda self: 2})())
    assert [info["status"] for info in infos] == ["in_progress"] * 14 + ["immobilized"]


def test_time_up_truncates_the_episode(environments):
    env = environments(track="pitlane-oval", mode="evaluation", laps=100)
    env.unwrapped.config["max_steps"] = 40
    env.reset(seed=0)
    driver = CentreLineDriver(env.unwrapped)
    # The reset is step 1 (DeepRacer's prepare step), so the 39th step() is step 40.
    endings = [env.step(driver.act())[2:4] for _ in range(39)]
    assert endings == [(False, False)] * 38 + [(False, True)]


@pytest.mark.parametrize("name", tracks.names(origin="pitlane"))
def test_the_reward_params_have_every_key_with_the_right_types_and_ranges(environments, name):
    env = environments(track=name, race_type="HEAD_TO_BOT", bots={"count": 2})
    env.reset(seed=0)
    seen = []
    for info in drive(env, steps=60):
        params = info["params"]
        seen.append(params)
        assert set(params) == REWARD_KEYS | OBJECT_KEYS
        for key in (
            "all_wheels_on_track",
            "is_left_of_center",
            "is_offtrack",
            "is_crashed",
            "is_reversed",
        ):
            assert type(params[key]) is bool, key
        for key in (
            "x",
            "y",
            "heading",
            "distance_from_center",
            "progress",
            "speed",
            "steering_angle",
            "track_width",
            "track_length",
            "projection_distance",
            "sim_time",
        ):
            assert type(params[key]) is float, key
        assert type(params["steps"]) is float
        assert -180 < params["heading"] <= 180
        assert 0 <= params["progress"] <= 100
        assert 0 <= params["distance_from_center"] <= params["track_width"]
        assert 0 <= params["projection_distance"] < params["track_length"]
        assert params["sim_time"] == pytest.approx(params["steps"] / 15)
        assert all(type(p) is tuple and len(p) == 2 for p in params["waypoints"])
        behind, ahead = params["closest_waypoints"]
        assert ahead == behind + 1  # never wraps to 0: the closing point is the last index
        assert len(params["objects_location"]) == 2
        assert set(params["closest_objects"]) <= {0, 1}
    assert seen[0] is not seen[1] and seen[0]["waypoints"] is not seen[1]["waypoints"]
    assert seen[0]["steps"] == 2.0 and seen[-1]["steps"] == len(seen) + 1  # 1 is prepare


def test_the_params_point_is_014_m_ahead_of_base_link(environments):
    env = environments(track="pitlane-oval")
    env.reset(seed=0)
    infos = drive(env, steps=5)
    params, row = infos[-1]["params"], infos[-1]["trace"]
    car = env.unwrapped.car
    ahead = car.spec.base_link + 0.14  # our origin is the rear axle
    assert params["x"] == pytest.approx(car.x + ahead * math.cos(car.yaw))
    assert params["y"] == pytest.approx(car.y + ahead * math.sin(car.yaw))
    assert (params["x"], params["y"]) == (row.X, row.Y)
    assert params["heading"] == pytest.approx(math.degrees(car.yaw))


def test_a_time_trial_has_the_object_keys_with_deepracers_defaults(environments):
    env = environments(track="kidney-bean", direction="clockwise")
    env.reset(seed=0)
    params = drive(env, steps=3)[-1]["params"]
    assert set(params) == REWARD_KEYS | OBJECT_KEYS
    assert params["closest_objects"] == [0, 0] and params["object_in_camera"] is False
    assert all(params[key] == [] for key in OBJECT_KEYS - {"closest_objects", "object_in_camera"})
    assert params["is_reversed"] is True


def test_a_reward_function_sees_commanded_speed_and_steering(environments):
    seen = []
    env = environments(reward_fn=lambda params: seen.append(params) or 1.0)
    env.reset(seed=0)
    env.step(0)  # -30° at 0.5 m/s
    env.step(9)  # 30° at 1.0 m/s
    assert [(p["steering_angle"], p["speed"]) for p in seen] == [(-30.0, 0.5), (30.0, 1.0)]


@pytest.mark.parametrize(
    ("value", "message"),
    [(float("nan"), "finite number"), (2e5, "within ±100000"), ("fast", "not a number"),
     (None, "not a number")],
)  # fmt: skip
def test_a_reward_that_is_not_a_usable_number_is_an_error(environments, value, message):
    env = environments(reward_fn=lambda params: value)
    env.reset(seed=0)
    with pytest.raises(RewardError, match=message):
        env.step(0)


def test_integer_boolean_and_numpy_rewards_are_accepted(environments):
    for value, expected in ((3, 3.0), (True, 1.0), (np.float32(0.5), 0.5)):
        env = environments(reward_fn=lambda params, value=value: value)
        env.reset(seed=0)
        assert env.step(0)[1] == expected


def test_an_evaluation_penalty_freezes_the_car_then_puts_it_back(environments):
    env = environments(
        track="pitlane-oval", mode="evaluation", laps=1, penalties={"off_track": 2.0, "crash": 5.0}
    )
    env.reset(seed=0)
    drive(env, steps=20)
    infos = drive(env, head_for_the_border(env), until="off_track")
    assert infos[-1]["status"] == "off_track" and infos[-1]["off_tracks"] == 1
    paused = drive(env, steps=30)
    assert [info["status"] for info in paused] == ["pause"] * 30
    assert paused[-1]["resets"] == 1
    assert env.unwrapped.track.contains(env.unwrapped.car.position)
    assert paused[-1]["trace"].pause_duration == pytest.approx(2.0)
    finish = drive(env)
    assert finish[-1]["status"] == "lap_complete"
    # The lap's time includes the 2 s the car stood still.
    (lap,) = finish[-1]["lap_times"]
    assert lap == pytest.approx(env.unwrapped.sim_time)
    assert lap > env.unwrapped.track.length / 1.0 + 2.0


def test_an_evaluation_episode_ends_where_the_car_would_be_put_back_once_too_often(environments):
    env = environments(
        track="pitlane-oval",
        mode="evaluation",
        laps=1,
        max_resets=1,
        penalties={"off_track": 0.0, "crash": 0.0},
    )
    env.reset(seed=0)
    drive(env, steps=20)
    put_back = drive(env, head_for_the_border(env), until="off_track")
    assert put_back[-1]["resets"] == 1 and not put_back[-1]["trace"].done
    ended = drive(env, head_for_the_border(env), until="off_track")
    assert ended[-1]["status"] == "off_track" and ended[-1]["trace"].done
    assert ended[-1]["resets"] == 1 and ended[-1]["off_tracks"] == 2
    assert not ended[-1]["lap_times"] and 0 < ended[-1]["progress"] < 100


def test_the_training_start_advances_five_percent_each_episode(environments):
    env = environments(track="pitlane-oval", start=0.1)
    length = env.unwrapped.track.length
    env.reset(seed=0)
    for episode in range(3):
        if episode:
            env.reset()
        assert env.unwrapped._distance == pytest.approx((0.1 + 0.05 * episode) * length, abs=0.02)


def test_lidar_sees_a_box_behind_and_sector_lidar_marks_its_sector(environments):
    for lidar in ("LIDAR", "SECTOR_LIDAR"):
        env = environments(
            track="pitlane-oval",
            race_type="OBJECT_AVOIDANCE",
            objects={"count": 1},
            sensors=["FRONT_FACING_CAMERA", lidar],
        )
        env.reset(seed=0)
        car = env.unwrapped
        (box,) = car.traffic.actors
        # the car 0.55 m past the box, driving on: simapp's laser faces backwards
        x, y, heading = car.track.point_at(box.distance + 0.55, box.offset)
        car.car.place(float(x), float(y), float(heading))
        observation = car._observe()[lidar]
        if lidar == "LIDAR":
            assert observation.shape == (64,) and observation.dtype == np.float32
            assert observation[28:36].max() < 0.6  # straight behind
            assert observation[:8].min() == 1.0  # ahead on the left: nothing
        else:
            assert observation.tolist() == [0, 0, 0, 1, 1, 0, 0, 0]


def test_the_camera_sees_a_dark_track_below_the_horizon_and_stereo_differs(environments):
    env = environments(track="speedway", sensors=["STEREO_CAMERAS"], start=0.1)
    observation, _ = env.reset(seed=0)
    left, right = observation["STEREO_CAMERAS"]
    assert left.shape == (120, 160)
    # above the horizon (row 26.2), the walls round simapp's fields and the background over
    # them; ahead, the dark road
    room = env.unwrapped._cameras[0].room
    assert np.isin(left[:26], (room.edge, room.background)).all()
    assert np.median(left[90:]) < 100
    assert np.abs(left.astype(int) - right.astype(int)).mean() > 0.5


def test_a_deepracer_file_written_here_loads_and_drives(environments, tmp_path):
    theta = np.linspace(0, 2 * np.pi, 120)
    circle = np.column_stack([np.cos(theta), np.sin(theta)])
    array = np.hstack([circle * 2.5, circle * 2.0, circle * 3.0])  # a 1 m wide ring
    path = tmp_path / "ring.npy"
    np.save(path, array)
    env = environments(track=str(path), mode="evaluation", laps=1, action_space=CONTINUOUS)
    env.reset(seed=0)
    assert drive(env)[-1]["status"] == "lap_complete"


@pytest.mark.parametrize(
    ("settings", "error", "message"),
    [
        ({"track": "monza"}, TrackError, "No track named 'monza'"),
        ({"direction": "sideways"}, ConfigError, "direction must be one of"),
        ({"track": "championship-circuit", "direction": "clockwise"}, TrackError,
         "cannot be driven clockwise"),
        ({"sensors": ["LIDAR"]}, ConfigError, "exactly one camera"),
        ({"sensors": ["FRONT_FACING_CAMERA", "STEREO_CAMERAS"]}, ConfigError,
         "exactly one camera"),
        ({"sensors": ["FRONT_FACING_CAMERA", "RADAR"]}, ConfigError, "Unknown sensor 'RADAR'"),
        ({"action_space": [{"steering_angle": 45, "speed": 1}, {"steering_angle": 0, "speed": 1}]},
         ConfigError, "Steering angle in action 0 is -30 to 30 degrees, not 45"),
        ({"action_space": [{"steering_angle": 0, "speed": 5}, {"steering_angle": 0, "speed": 1}]},
         ConfigError, "Speed in action 0 is 0.1 to 4 m/s, not 5"),
        ({"action_space": [{"steering_angle": 0, "speed": 1}]}, ConfigError, "2 to 30 actions"),
        ({"action_space": {"steering_angle": {"low": 10, "high": -10},
                           "speed": {"low": 1, "high": 2}}}, ConfigError, "above the lowest"),
        ({"race_type": "DRAG_RACE"}, ConfigError, "race type must be one of"),
        ({"race_type": "OBJECT_AVOIDANCE", "objects": {"count": 7}}, ConfigError,
         "number of boxes must be a whole number from 1 to 6"),
        ({"race_type": "HEAD_TO_BOT", "bots": {"speed": 7}}, ConfigError, "0.2-6.0 m/s"),
        ({"objects": {"count": 2}}, ConfigError, "only in an OBJECT_AVOIDANCE race"),
        ({"mode": "evaluation", "laps": 0}, ConfigError, "laps must be a whole number"),
        ({"penalties": {"off_track": -1}}, ConfigError, "off-track penalty is 0-60 seconds"),
        ({"penalties": {"crash_s": 1}}, ConfigError, "Unknown penalties setting 'crash_s'"),
        ({"start": 1.5}, ConfigError, "fraction of the lap"),
    ],
)  # fmt: skip
def test_bad_settings_get_clear_errors(environments, settings, error, message):
    with pytest.raises(error, match=message):
        environments(**settings)
