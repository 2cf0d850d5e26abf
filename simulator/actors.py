"""Boxes and bot cars: where they stand or drive along the track, for the world and the cameras."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from simulator.camera import Solid
from simulator.car import CarSpec
from simulator.config import Bots, Objects
from simulator.tracks import Track

BOX_SIZE = (0.5, 0.4, 0.3)  # [m] length along the track, width across it, height
BOX_SHADE = (226, (64, 160, 232))  # (gray, BGR): a bright cardboard-orange box
BOT_SHADE = (120, (200, 90, 40))  # (gray, BGR): a blue bot car
LANE_CHANGE_TIME = 1.0  # [s] to move from one lane to the other
LANE_CHANGE_EVERY = (3.0, 8.0)  # [s] between a bot's lane changes, drawn at random
START_CLEARANCE = (-0.6, 1.2)  # [m] before and after the car's start no box may stand
FAR_AWAY = 1e4  # [m] where a rival waits until the race places it


@dataclass
class Actor:
    kind: str  # "box", "bot" or "rival"
    distance: float  # [m] along the centre line
    offset: float  # [m] left of the centre line
    length: float
    width: float
    height: float
    speed: float = 0.0  # [m/s]
    target_offset: float = 0.0
    next_lane_change: float = math.inf  # [s] of simulated time
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0  # [rad]
    ghost: bool = False  # a rival serving a crash's penalty: seen, but nothing crashes into it


class Traffic:
    """The boxes (OBJECT_AVOIDANCE) or bot cars (HEAD_TO_BOT) of one episode."""

    def __init__(
        self,
        track: Track,
        objects: Objects | None,
        bots: Bots | None,
        rivals: int = 0,
        rival_shades: tuple = (),
    ) -> None:
        self.track = track
        self.objects = objects
        self.bots = bots
        self.rivals = rivals  # other racers' cars, placed from outside (simulator.head_to_head)
        self.rival_shades = rival_shades  # each rival's (gray, BGR); BOT_SHADE where none
        self.lane = track.width / 4
        self.actors: list[Actor] = []

    @property
    def present(self) -> bool:
        return self.objects is not None or self.bots is not None or self.rivals > 0

    def reset(self, car_distance: float, rng: np.random.Generator) -> float:
        """Place the actors for an episode starting at ``car_distance``; returns the start
        distance, moved forward past a box that would stand on it."""
        self.actors = []
        length = self.track.length
        if self.objects is not None:
            count = self.objects.count
            if self.objects.randomize:
                distances = _spread(rng, count, length, min_gap=min(2.0, length / (2 * count)))
                sides = rng.choice([-1.0, 1.0], size=count)
            else:
                distances = (np.arange(count) + 0.5) * length / count
                sides = np.where(np.arange(count) % 2 == 0, 1.0, -1.0)
            box_length, box_width, box_height = BOX_SIZE
            for distance, side in zip(distances, sides, strict=True):
                self.actors.append(
                    Actor(
                        "box", float(distance), side * self.lane, box_length, box_width, box_height
                    )
                )
            car_distance = self._clear_start(car_distance)
        if self.bots is not None:
            spec = CarSpec()
            count = self.bots.count
            for i in range(count):
                side = 1.0 if i % 2 == 0 else -1.0
                bot = Actor(
                    "bot",
                    (car_distance + (i + 1) * length / (count + 1)) % length,
                    side * self.lane,
                    spec.length,
                    spec.width,
                    spec.height,
                    speed=self.bots.speed,
                    target_offset=side * self.lane,
                )
                if self.bots.lane_changes:
                    bot.next_lane_change = float(rng.uniform(*LANE_CHANGE_EVERY))
                self.actors.append(bot)
        spec = CarSpec()
        for _ in range(self.rivals):  # off the field until the race places them
            rival = Actor("rival", 0.0, 0.0, spec.length, spec.width, spec.height)
            rival.x = rival.y = FAR_AWAY
            self.actors.append(rival)
        self._update_poses()
        return car_distance

    def place_rivals(self, poses, ghosts=None) -> None:
        """Where the other racers' cars are now: (x, y, yaw) of each, in order, and whether each
        is a ghost (``ghosts``; none by default)."""
        rivals = [actor for actor in self.actors if actor.kind == "rival"]
        ghosts = [False] * len(rivals) if ghosts is None else ghosts
        for rival, (x, y, yaw), ghost in zip(rivals, poses, ghosts, strict=True):
            rival.x, rival.y, rival.yaw, rival.ghost = float(x), float(y), float(yaw), bool(ghost)

    def step(self, dt: float, sim_time: float, rng: np.random.Generator) -> None:
        """Drive the bot cars on for ``dt`` seconds."""
        if self.bots is None:
            return
        lateral_rate = 2 * self.lane / LANE_CHANGE_TIME
        for bot in self.actors:
            if bot.kind != "bot":
                continue
            if sim_time >= bot.next_lane_change:
                bot.target_offset = -bot.target_offset
                bot.next_lane_change = sim_time + float(rng.uniform(*LANE_CHANGE_EVERY))
            gap = bot.target_offset - bot.offset
            bot.offset += max(-lateral_rate * dt, min(lateral_rate * dt, gap))
            bot.distance = (bot.distance + bot.speed * dt) % self.track.length
        self._update_poses()

    def solids(self, colour: bool = False) -> list[Solid]:
        pick = 1 if colour else 0
        shades, rivals = [], iter(self.rival_shades)
        for actor in self.actors:
            if actor.kind == "rival":
                shades.append(next(rivals, BOT_SHADE)[pick])
            else:
                shades.append((BOX_SHADE if actor.kind == "box" else BOT_SHADE)[pick])
        return [
            Solid(a.x, a.y, a.yaw, a.length, a.width, a.height, shade)
            for a, shade in zip(self.actors, shades, strict=True)
        ]

    def _update_poses(self) -> None:
        driven = [actor for actor in self.actors if actor.kind != "rival"]
        if not driven:
            return
        distances = np.array([a.distance for a in driven])
        offsets = np.array([a.offset for a in driven])
        xs, ys, headings = self.track.point_at(distances, offsets)
        for actor, x, y, heading in zip(driven, xs, ys, headings, strict=True):
            actor.x, actor.y, actor.yaw = float(x), float(y), float(heading)

    def _clear_start(self, car_distance: float) -> float:
        """Move the start forward past any box that stands on it."""
        length = self.track.length
        before, after = START_CLEARANCE
        for _ in range(len(self.actors) + 1):
            half = length / 2
            blocking = [
                a
                for a in self.actors
                if before <= (a.distance - car_distance + half) % length - half <= after
            ]
            if not blocking:
                break
            last = max(blocking, key=lambda a: (a.distance - car_distance) % length)
            car_distance = (last.distance + last.length / 2 + 0.5) % length
        return car_distance


def _spread(rng: np.random.Generator, count: int, length: float, min_gap: float) -> np.ndarray:
    """``count`` random distances along a lap of ``length``, at least ``min_gap`` apart."""
    for _ in range(100):
        distances = np.sort(rng.uniform(0.0, length, size=count))
        gaps = np.diff(np.concatenate([distances, distances[:1] + length]))
        if gaps.min() >= min_gap:
            return distances
    return (np.arange(count) + rng.uniform()) * length / count % length
