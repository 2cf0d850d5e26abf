"""Model against model (simulator.head_to_head): cars on one track at once, on simapp's grid,
seeing and hitting one another, each with its own trace and results."""

from __future__ import annotations

import numpy as np
import pytest

from simulator.controller import CentreLineDriver
from simulator.env import DeepRacerEnv
from simulator.head_to_head import START_OFFSET, grid, race

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


def test_a_faster_car_behind_runs_into_the_slower_one_and_both_have_their_traces():
    envs = cars()
    drivers = [
        CentreLineDriver(env, speed=speed) for env, speed in zip(envs, (1.0, 3.0), strict=True)
    ]
    results = race(envs, [lambda _, d=driver: d.act() for driver in drivers], seed=0)
    slow, fast = results
    assert fast.counts["crashes"] >= 1 or slow.counts["crashes"] >= 1
    assert len(slow.trace) > 10 and len(fast.trace) == len(slow.trace)
    assert {row.episode for row in fast.trace} == {0}
    ended = [result.status for result in results]
    assert "race_over" in ended  # the first car done ended the race (DONE_CONDITION any)


def test_a_race_needs_two_to_four_cars():
    with pytest.raises(ValueError, match="2 to 4 cars"):
        race(cars()[:1], [lambda _: np.zeros(2, dtype=np.float32)])


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
