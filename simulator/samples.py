"""Typical situations on a track, as reward params: what a racer's reward function is tried on
before training, so they see what it returns."""

from __future__ import annotations

import math
from dataclasses import dataclass

import gymnasium

import simulator
from simulator.env import DeepRacerEnv
from simulator.params import object_param_defaults

LAP_SPEED = 1.0  # [m/s] the pace the samples' step counts assume


@dataclass(frozen=True)
class Situation:
    name: str
    description: str
    params: dict


def situations(track: str, direction: str = "counterclockwise") -> list[Situation]:
    """Start line, mid-lap, off track, finish and near an object, on ``track``."""
    env: DeepRacerEnv = gymnasium.make(
        simulator.ENV_ID,
        track=track,
        direction=direction,
        race_type="OBJECT_AVOIDANCE",
        objects={"count": 1},
    ).unwrapped
    try:
        env.reset(seed=0)
        length = env.track.length
        half_width = env.track.width / 2
        (box,) = env.traffic.actors
        # one situation a row (a table: the formatter leaves it as it is)
        found = [
            _at(env, "start", "On the start line, at rest", 0.0, 0.0, 0.0, 0.0, 0.0),
            _at(env, "mid-lap", "Mid-lap at speed, a little left of the centre line, turning",
                0.62 * length, 0.12, 62.0, 10.0, 1.5),
            _at(env, "off-track", "All four wheels over the right-hand border",
                0.3 * length, -(half_width + 0.35), 30.0, -15.0, 1.0),
            _at(env, "finish", "Crossing the finish line at the end of a lap",
                length - 0.02, 0.0, 100.0, 0.0, 1.5),
            _at(env, "near-object", "A box 0.6 m ahead in the car's lane",
                box.distance - box.length / 2 - 0.6 - env.car.spec.report_offset,
                box.offset, 40.0, 0.0, 1.0),
        ]  # fmt: skip
    finally:
        env.close()
    for situation in found[:-1]:  # only the last one has an object: the others are time trials
        situation.params.update(object_param_defaults())
    return found


def _at(
    env: DeepRacerEnv,
    name: str,
    description: str,
    distance: float,
    offset: float,
    progress: float,
    steering: float,
    speed: float,
) -> Situation:
    x, y, heading = env.track.point_at(distance % env.track.length, offset)
    back = env.car.spec.report_offset
    heading = float(heading)
    env.car.place(float(x) - back * math.cos(heading), float(y) - back * math.sin(heading), heading)
    env.progress = progress
    # Step 1 is the episode's prepare step, as DeepRacer counts steps.
    env.steps = 1 + round(progress / 100 * env.track.length / LAP_SPEED * env.config["control_hz"])
    env.sim_time = (env.steps - 1) * env.dt
    env.clock = env.steps * env.dt  # as if the worker had begun with this episode
    return Situation(name, description, env.current_params(steering=steering, speed=speed))
