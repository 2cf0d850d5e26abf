"""Model against model (simulator.head_to_head): cars on one track at once, on simapp's grid,
seeing and hitting one another, each with its own trace and results, driven by the one episode
loop (rl.episode.Fleet with race=True) as an evaluation's race is."""

from __future__ import annotations

import numpy as np

from rl.episode import Fleet
from simulator.controller import CentreLineDriver
from simulator.env import DeepRacerEnv
from simulator.head_to_head import START_OFFSET, grid

CONTINUOUS = {"steering_angle": {"low": -30.0, "high": 30.0}, "speed": {"low": 0.5, "high": 4.0}}
RED, BLUE = (40, 40, 220), (220, 90, 40)


def cars(track: str = "rookie-loop", **settings) -> list[DeepRacerEnv]:
    return [
        DeepRacerEnv(
            track=track,
            mode="evaluation",
            laps=1,
            action_space=CONTINUOUS,
            sensors=["FRONT_FACING_CAMERA", "LIDAR"],
            rivals=1,
            grid=place,
            car_colour=own,
            rival_colours=[other],
            penalties={"crash": 2.0},
            **settings,
        )
        for place, own, other in zip((0, 1), (RED, BLUE), (BLUE, RED), strict=True)
    ]


def test_the_grid_is_simapps_each_car_behind_the_last_in_the_other_lane():
    track = DeepRacerEnv(track="rookie-loop").track  # counter-clockwise: the inner lane is left
    lane = track.width / 4
    assert grid(track, 3) == [(0.0, -lane), (-START_OFFSET, lane), (-2 * START_OFFSET, -lane)]
    reversed_track = track.with_direction("clockwise")
    assert grid(reversed_track, 2) == [(0.0, lane), (-START_OFFSET, -lane)]


def test_each_car_sees_the_other_and_the_lidar_meets_it():
    leader, follower = cars()
    for env in (leader, follower):
        env.reset(seed=0)
    alone = follower._observe()["FRONT_FACING_CAMERA"][0]  # the rival off the field
    leader.place_rivals([follower.body_pose])
    follower.place_rivals([leader.body_pose])
    # the follower's camera sees the leader ahead, 0.75 m on and a lane over
    seen = follower._observe()["FRONT_FACING_CAMERA"][0]
    assert (seen != alone).sum() > 500
    # the leader's lidar faces backwards: the follower 0.75 m behind is within its 1 m
    assert leader._observe()["LIDAR"].min() < 1.0


class Driver:
    """A policy as the fleet calls it: the centre-line driver, at a constant speed."""

    def __init__(self, env: DeepRacerEnv, speed: float) -> None:
        self.driver = CentreLineDriver(env, speed=speed)

    def drive_rows(self, observations):
        return [self.driver.act() for _ in observations]

    def command(self, action, discrete: bool):
        return action


def test_a_faster_car_behind_runs_into_the_slower_one_and_each_drives_its_own_race():
    envs = cars()
    fleet = Fleet(envs, policy=None, race=True)
    for car, speed in zip(fleet.cars, (1.0, 3.0), strict=True):
        car.policy = Driver(car.env, speed)
        fleet.start(car, "evaluate", seed=0)
    ended = []
    while fleet.driving():
        ended += [(car.index, len(car.driven.trace)) for car in fleet.step()]
    slow, fast = envs
    assert fast.counts["crashes"] >= 1  # it ran into the slow car, and served its penalties
    # the slow car finished first and was parked; the fast one drove on to its own lap's end
    (first, first_steps), (second, second_steps) = ended
    assert (first, second) == (0, 1) and second_steps > first_steps > 10
    assert [env.status for env in envs] == ["lap_complete", "lap_complete"]
    assert len(fast.lap_times) == len(slow.lap_times) == 1


def test_a_car_that_hits_a_rival_serves_its_penalty_where_it_stands_as_a_ghost():
    leader, follower = cars()
    for env in (leader, follower):
        env.reset(seed=0)
    ahead = np.array([0.0, 0.5], dtype=np.float32)  # straight on, slowly
    follower.place_rivals([follower.body_pose])  # a rival's car on the follower's own spot
    follower.step(ahead)
    assert follower.status == "crashed" and follower.ghost and follower.counts["crashes"] == 1
    stood = follower.car.position
    for _ in range(round(2.0 / follower.dt)):  # the crash penalty: 2 s, in place
        follower.step(ahead)
    assert follower.counts["resets"] == 0 and np.allclose(follower.car.position, stood)
    # nothing crashes into a ghost, nor a ghost into anything, until it comes clear
    leader.place_rivals([leader.body_pose], [True])
    leader.step(ahead)
    assert leader.status != "crashed" and follower.counts["crashes"] == 1
    while follower.ghost:
        follower.step(ahead)
    assert follower.status == "in_progress" and follower.counts["crashes"] == 1
