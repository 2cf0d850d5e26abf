"""A scripted driver that follows the centre line: a racer's first look at a track, and a check
that every track can be driven."""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from simulator.config import ContinuousActions
from simulator.env import DeepRacerEnv


class CentreLineDriver:
    """Pure pursuit of a point ``lookahead`` metres ahead on the centre line, at ``speed``."""

    def __init__(self, env: DeepRacerEnv, speed: float = 1.0, lookahead: float = 0.45) -> None:
        self.env = env
        self.speed = speed
        self.lookahead = lookahead

    def steering(self) -> float:
        """[deg] the steering that points the car at the pursuit point, within ±30°."""
        env, car = self.env, self.env.car
        here = float(env.track.project_points([(car.x, car.y)]).distance[0])
        x, y, _ = env.track.point_at(here + self.lookahead)
        alpha = math.atan2(float(y) - car.y, float(x) - car.x) - car.yaw
        alpha = math.atan2(math.sin(alpha), math.cos(alpha))
        distance = max(math.hypot(float(x) - car.x, float(y) - car.y), 1e-6)
        steering = math.degrees(math.atan2(2 * car.spec.wheelbase * math.sin(alpha), distance))
        return max(-car.spec.max_steering, min(car.spec.max_steering, steering))

    def act(self):
        """The action, in the environment's action space, closest to steering at ``speed``."""
        steering = self.steering()
        actions = self.env.actions
        if isinstance(actions, ContinuousActions):
            (s_low, s_high), (v_low, v_high) = actions.steering, actions.speed
            return np.array(
                [2 * (steering - s_low) / (s_high - s_low) - 1,
                 2 * (self.speed - v_low) / (v_high - v_low) - 1],
                dtype=np.float32,
            )  # fmt: skip
        table = np.array(actions.actions)
        cost = np.abs(table[:, 0] - steering) / 30.0 + np.abs(table[:, 1] - self.speed)
        return int(np.argmin(cost))


@dataclass
class RolloutStats:
    steps: int = 0
    episodes: int = 0
    reward: float = 0.0
    statuses: Counter = field(default_factory=Counter)


def drive(
    env,
    steps: int,
    *,
    random_actions: bool = False,
    seed: int = 0,
    report: Callable[[RolloutStats], None] | None = None,
    every: float = 0.25,
) -> RolloutStats:
    """Step ``env`` (reset already) ``steps`` times with the centre-line driver or random actions,
    resetting after each episode; ``report`` is called at most every ``every`` seconds."""
    driver = CentreLineDriver(env.unwrapped, speed=1.0)
    env.action_space.seed(seed)
    stats = RolloutStats()
    last_report = time.perf_counter()
    while stats.steps < steps:
        action = env.action_space.sample() if random_actions else driver.act()
        _, reward, terminated, truncated, info = env.step(action)
        stats.steps += 1
        stats.reward += reward
        if terminated or truncated:
            stats.statuses[info["status"]] += 1
            stats.episodes += 1
            env.reset()
        if report is not None and time.perf_counter() - last_report >= every:
            report(stats)
            last_report = time.perf_counter()
    return stats
