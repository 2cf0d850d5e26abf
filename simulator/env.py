"""The DeepRacer environment: ``gymnasium.make("Pitlane/DeepRacer-v0", ...)``."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from simulator import config
from simulator.actors import Traffic
from simulator.camera import Lens, Mount, PerspectiveView
from simulator.car import Car, CarSpec
from simulator.config import ContinuousActions, DiscreteActions
from simulator.rewards import checked_reward, follow_centre_line
from simulator.texture import render
from simulator.trace import SimTraceRow
from simulator.tracks import Track, load
from simulator.world import World


def default_config() -> dict[str, Any]:
    """The physical constants of the simulation, with their units."""
    return {
        "control_hz": 15,  # [Hz] DeepRacer's control rate: one step is 1/15 s
        "physics_substeps": 4,  # per control step (60 Hz integration)
        "max_steps": 10_000,  # per episode, then time_up
        "start_advance": 0.05,  # [fraction of the lap] the training start moves per episode
        "stall_steps": 15,  # consecutive steps that make reversed or immobilized
        "immobilized_distance": 0.0003,  # [m] moved per step under which the car is stuck
        "camera_size": (160, 120),  # [px] width, height
        "camera_fov": 120.0,  # [deg] horizontal
        "camera_mount": (0.12, 0.12, 25.0),  # forward [m], height [m], pitch down [deg]
        "stereo_baseline": 0.06,  # [m] between the stereo cameras
        "camera_texture_ppm": 64,  # [px/m] of the track image the camera projects
        "camera_sky": 150,  # gray level above the horizon
        "lidar_rays": 64,
        "lidar_fov": 300.0,  # [deg] ±150
        "lidar_range": (0.15, 1.0),  # [m] after clipping
        "lidar_height": 0.1,  # [m] above the ground
        "sector_lidar_sectors": 8,
    }


TERMINAL = ("off_track", "crashed", "reversed", "immobilized", "lap_complete")


class DeepRacerEnv(gym.Env):
    """A 1/18-scale car on a DeepRacer track, seen through its sensors, rewarded by a racer's
    reward function.

    **Actions**: with a discrete action space, ``Discrete(n)``: the index of an action of the
    ``model_metadata.json`` list. With a continuous one, ``Box(-1, 1, (2,), float32)``: steering
    and speed, each scaled linearly onto its [low, high] range (and clipped there).

    **Observations**: a ``Dict`` keyed by sensor name. ``FRONT_FACING_CAMERA``: ``uint8`` (1, 120,
    160), grayscale; ``STEREO_CAMERAS``: (2, 120, 160), left then right; ``LIDAR``: ``float32``
    (64,), metres over ±150° (left is positive), clipped to 0.15-1.0; ``SECTOR_LIDAR``:
    ``MultiBinary(8)``, each sector 1 when something is within range.

    **Reward**: ``reward_fn(params)``, where ``params`` is the dict of DeepRacer's reward-function
    input (REFERENCE section 1). It must return a finite real number within ±1e5.

    **Starting state**: the car at rest on the centre line, heading along the track. In training
    the start advances ``start_advance`` of the lap every episode, beginning at ``start``; in
    evaluation every episode starts at ``start`` (0: the start line).

    **Episode end**: training ends on any terminal status (off_track, crashed, reversed,
    immobilized, lap_complete), evaluation after ``laps`` laps; both truncate at ``max_steps``
    (time_up). In evaluation, going off track or crashing freezes the car for the penalty while the
    clock runs (status ``pause``) and then puts it back on the centre line at its last progress;
    reversing or being immobilized puts it back without a penalty. Lap times include penalties.

    **Arguments**: ``track`` (a built-in name or a DeepRacer ``.npy`` path), ``direction``,
    ``sensors``, ``action_space``, ``race_type``, ``objects`` ({count, randomize}), ``bots``
    ({count, speed, lane_changes}), ``mode``, ``laps``, ``penalties`` ({off_track, crash} in
    seconds), ``start`` (fraction of the lap), ``reward_fn``, ``seed``, ``render_mode``
    ("rgb_array": the 640 x 480 spectator view), ``car`` (a ``CarSpec``), ``car_colour`` (BGR).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(
        self,
        track: str | Path = "rookie-loop",
        direction: str = "counterclockwise",
        sensors: Sequence[str] = ("FRONT_FACING_CAMERA",),
        action_space: Any = None,
        race_type: str = "TIME_TRIAL",
        objects: dict | None = None,
        bots: dict | None = None,
        mode: str = "training",
        laps: int = 3,
        penalties: dict | None = None,
        start: float = 0.0,
        reward_fn: Callable[[dict], float] | None = None,
        seed: int | None = None,
        render_mode: str | None = None,
        car: CarSpec | None = None,
        car_colour: tuple[int, int, int] = (40, 40, 220),
    ) -> None:
        self.config = default_config()
        self.track: Track = load(track).with_direction(config.choice(
            "The direction", direction, ("counterclockwise", "clockwise")))  # fmt: skip
        self.camera_name, self.lidar_name = config.sensors(sensors)
        self.actions = config.action_space(action_space)
        self.race_type = config.choice("The race type", race_type, config.RACE_TYPES)
        if race_type == "OBJECT_AVOIDANCE" and objects is None:
            objects = {}
        if race_type == "HEAD_TO_BOT" and bots is None:
            bots = {}
        self.traffic = Traffic(
            self.track, config.objects(objects, race_type), config.bots(bots, race_type)
        )
        self.mode = config.choice("The mode", mode, config.MODES)
        self.laps = config.positive_int("The number of laps", laps, 1, 100)
        self.penalties = config.penalties(penalties)
        self.start = config.fraction("The start", start)
        self.reward_fn = reward_fn or follow_centre_line
        if render_mode not in (None, "rgb_array"):
            raise config.ConfigError(f"The render mode must be rgb_array, not {render_mode!r}.")
        self.render_mode = render_mode
        self.car_colour = tuple(int(channel) for channel in car_colour)  # JSON gives a list

        self.car = Car(car, substeps=self.config["physics_substeps"])
        self.dt = 1.0 / self.config["control_hz"]
        self._build_spaces()
        self._build_sensors()
        self._world = World()
        spec = self.car.spec
        self._car_body = self._world.add_car(spec.length, spec.width, spec.height)
        self._actor_bodies = []
        self._waypoints = tuple(self.track.waypoints)
        self._spectator = None
        self._episode = -1
        self._seed = seed

    # Gymnasium API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is None and self._episode < 0:
            seed = self._seed
        super().reset(seed=seed)
        # A seed starts the run over: the same seed gives the same episodes, starts included.
        self._episode = 0 if seed is not None else self._episode + 1
        length = self.track.length
        if self.mode == "training":
            fraction = (self.start + self._episode * self.config["start_advance"]) % 1.0
        else:
            fraction = self.start
        start = self.traffic.reset(fraction * length, self.np_random)
        self._sync_actor_bodies()
        self._place_car(start)
        self.steps = 0
        self.sim_time = 0.0
        self.lap = 1
        self._lap_finished = False
        self.status = "prepare"
        self.lap_times: list[float] = []
        self._lap_started = 0.0
        self._travelled = 0.0
        self.progress = 0.0
        self._falling = self._stuck = 0
        self._pause_left = 0
        self._pause_duration = 0.0
        self._resume_at, self._resume_travelled = self._distance, 0.0
        self.counts = dict.fromkeys(
            ("off_tracks", "crashes", "reversed", "immobilized", "resets"), 0
        )
        self._trail = [self.car.position]
        self._last_params: dict | None = None
        return self._observe(), self._info("prepare", None, 0.0, False)

    def step(self, action):
        self.steps += 1
        self.sim_time = self.steps * self.dt
        if self._lap_finished:
            self.lap += 1
            self._lap_finished = False
        if self._pause_left > 0:
            return self._paused_step()
        steering, speed = self._command(action)
        moved = self.car.step(speed, steering, self.dt)
        self.traffic.step(self.dt, self.sim_time, self.np_random)
        self._sync_actor_bodies()

        projection, on_track, crashed = self._where()

        previous = self._distance
        self._distance = float(projection.distance[4])
        delta = self._wrapped(self._distance - previous)
        self._travelled += delta
        self.progress = min(max(100.0 * self._travelled / self.track.length, 0.0), 100.0)
        self._falling = self._falling + 1 if delta < 0 else 0
        self._stuck = self._stuck + 1 if moved < self.config["immobilized_distance"] else 0

        stall = self.config["stall_steps"]
        if crashed:
            status = "crashed"
        elif not on_track.any():
            status = "off_track"
        elif self._falling >= stall:
            status = "reversed"
        elif self._stuck >= stall:
            status = "immobilized"
        elif self._travelled >= self.track.length:
            status = "lap_complete"
        else:
            status = "in_progress"
        if status == "in_progress":
            self._resume_at, self._resume_travelled = self._distance, self._travelled

        self.status = status  # known before the reward function runs, for reporting its failures
        params = self._params(projection, on_track, crashed, steering, speed, status)
        reward = self._reward(params)
        terminated, truncated = self._outcome(status)
        self._trail.append(self.car.position)
        info = self._info(status, params, reward, terminated or truncated, action=action)
        return self._observe(), reward, terminated, truncated, info

    def render(self):
        """The spectator view in RGB, as Gymnasium asks; ``spectator.render`` gives BGR."""
        if self.render_mode != "rgb_array":
            return None
        return cv2.cvtColor(self.spectator.render(self), cv2.COLOR_BGR2RGB)

    @property
    def spectator(self):
        """The renderer of what people watch, made on first use."""
        if self._spectator is None:
            from simulator.spectator import Spectator

            self._spectator = Spectator(self.track)
        return self._spectator

    def close(self) -> None:
        self._world.close()

    # Motion and statuses

    def _command(self, action) -> tuple[float, float]:
        if isinstance(self.actions, DiscreteActions):
            return self.actions.actions[int(action)]
        return self.actions.scale(np.asarray(action, dtype=np.float64))

    def _place_car(self, distance: float) -> None:
        """Put the car at rest so that its reported position is at ``distance`` on the centre."""
        x, y, heading = self.track.point_at(distance)
        back = self.car.spec.position_offset
        self.car.place(float(x) - back * math.cos(heading), float(y) - back * math.sin(heading),
                       float(heading))  # fmt: skip
        self._sync_car_body()
        self._distance = float(self.track.project_points([self.car.position]).distance[0])

    def _sync_car_body(self) -> None:
        c = self.car
        offset = c.spec.centre_offset
        self._world.place(self._car_body, c.x + offset * math.cos(c.yaw),
                          c.y + offset * math.sin(c.yaw), c.yaw)  # fmt: skip

    def _sync_actor_bodies(self) -> None:
        actors = self.traffic.actors
        while len(self._actor_bodies) < len(actors):
            actor = actors[len(self._actor_bodies)]
            self._actor_bodies.append(
                self._world.add_obstacle(actor.length, actor.width, actor.height)
            )
        for body, actor in zip(self._actor_bodies, actors, strict=False):
            self._world.place(body, actor.x, actor.y, actor.yaw)

    def _crashed(self) -> bool:
        if not self.traffic.present:
            return False
        self._sync_car_body()
        return bool(self._world.car_touches())

    def _outcome(self, status: str) -> tuple[bool, bool]:
        """(terminated, truncated) after a step with ``status``; applies evaluation's rules."""
        truncated = self.steps >= self.config["max_steps"]
        if self.mode == "training":
            return status in TERMINAL, truncated and status not in TERMINAL
        if status == "lap_complete":
            self.lap_times.append(self.sim_time - self._lap_started)
            self._lap_started = self.sim_time
            self._travelled -= self.track.length
            if len(self.lap_times) >= self.laps:
                return True, False
            self._lap_finished = True
        elif status in ("off_track", "crashed"):
            self.counts["off_tracks" if status == "off_track" else "crashes"] += 1
            seconds = self.penalties.off_track if status == "off_track" else self.penalties.crash
            self._pause_left = round(seconds / self.dt)
            if self._pause_left == 0:
                self._put_back()
        elif status in ("reversed", "immobilized"):
            self.counts[status] += 1
            self._put_back()
        return False, truncated

    def _paused_step(self):
        """A step frozen by a penalty: the clock runs, the car waits, then goes back on track."""
        self._pause_left -= 1
        self._pause_duration += self.dt
        if self._pause_left == 0:
            self._put_back()
        truncated = self.steps >= self.config["max_steps"]
        return self._observe(), 0.0, False, truncated, self._info("pause", None, 0.0, truncated)

    def _put_back(self) -> None:
        """Reset the car on the centre line at its last progress (DeepRacer's evaluation reset)."""
        self.counts["resets"] += 1
        self._place_car(self._resume_at)
        self._travelled = self._resume_travelled + self._wrapped(self._distance - self._resume_at)
        self._falling = self._stuck = 0

    def _wrapped(self, delta: float) -> float:
        """A difference of distances along the loop, in [-length/2, length/2)."""
        half = self.track.length / 2
        return (delta + half) % self.track.length - half

    # What the policy and the reward function see

    def _build_spaces(self) -> None:
        if isinstance(self.actions, DiscreteActions):
            self.action_space = spaces.Discrete(len(self.actions.actions))
        else:
            self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        width, height = self.config["camera_size"]
        channels = 2 if self.camera_name == "STEREO_CAMERAS" else 1
        observation = {
            self.camera_name: spaces.Box(0, 255, (channels, height, width), dtype=np.uint8)
        }
        low, high = self.config["lidar_range"]
        if self.lidar_name == "LIDAR":
            rays = self.config["lidar_rays"]
            observation["LIDAR"] = spaces.Box(low, high, (rays,), dtype=np.float32)
        elif self.lidar_name == "SECTOR_LIDAR":
            observation["SECTOR_LIDAR"] = spaces.MultiBinary(self.config["sector_lidar_sectors"])
        self.observation_space = spaces.Dict(observation)

    def _build_sensors(self) -> None:
        cfg = self.config
        texture = render(self.track, pixels_per_metre=cfg["camera_texture_ppm"])
        lens = Lens(*cfg["camera_size"], cfg["camera_fov"])
        forward, height, pitch = cfg["camera_mount"]
        if self.camera_name == "STEREO_CAMERAS":
            half = cfg["stereo_baseline"] / 2
            lefts = (half, -half)
        else:
            lefts = (0.0,)
        self._cameras = [
            PerspectiveView(texture, lens, Mount(forward, height, pitch, left), cfg["camera_sky"])
            for left in lefts
        ]
        angles = np.radians(
            np.linspace(-cfg["lidar_fov"] / 2, cfg["lidar_fov"] / 2, cfg["lidar_rays"])
        )
        self._lidar_angles = angles

    def _observe(self) -> dict[str, np.ndarray]:
        c = self.car
        solids = self.traffic.solids() if self.traffic.present else ()
        frames = [camera.render(c.x, c.y, c.yaw, solids) for camera in self._cameras]
        observation = {self.camera_name: np.stack(frames)}
        if self.lidar_name is not None:
            distances = self._lidar()
            if self.lidar_name == "LIDAR":
                observation["LIDAR"] = distances.astype(np.float32)
            else:
                sectors = np.array_split(distances, self.config["sector_lidar_sectors"])
                high = self.config["lidar_range"][1]
                observation["SECTOR_LIDAR"] = np.array(
                    [int((sector < high).any()) for sector in sectors], dtype=np.int8
                )
        return observation

    def _lidar(self) -> np.ndarray:
        low, high = self.config["lidar_range"]
        c = self.car
        angles = c.yaw + self._lidar_angles
        directions = np.column_stack([np.cos(angles), np.sin(angles)])
        origin = (*c.point_ahead(c.spec.centre_offset), self.config["lidar_height"])
        return np.clip(self._world.cast_rays(origin, directions, high), low, high)

    def _where(self):
        """The projection of the wheels and the reported position, which wheels are on the track,
        and whether the car touches an obstacle."""
        wheels_and_point = np.vstack([self.car.wheels(), [self.car.position]])
        projection = self.track.project_points(wheels_and_point)
        on_track = projection.offset[:4] <= projection.half_width[:4]
        return projection, on_track, self._crashed()

    def current_params(self, *, steering: float = 0.0, speed: float = 0.0) -> dict:
        """The reward params for the car where it is now, as a step would give them: for showing a
        racer what their reward function returns in a given situation."""
        projection, on_track, crashed = self._where()
        status = "off_track" if not on_track.any() else "in_progress"
        return self._params(projection, on_track, crashed, steering, speed, status)

    def _params(self, projection, on_track, crashed, steering, speed, status) -> dict:
        track, c = self.track, self.car
        x, y = c.position
        segment = int(projection.segment[4])
        params = {
            "all_wheels_on_track": bool(on_track.all()),
            "x": x,
            "y": y,
            "heading": math.degrees(c.yaw) if c.yaw > -math.pi else 180.0,
            "distance_from_center": float(projection.offset[4]),
            "is_left_of_center": bool(projection.is_left[4]),
            "is_offtrack": status == "off_track",
            "is_crashed": crashed,
            "is_reversed": track.direction == "clockwise",
            "progress": self.progress,
            "steps": self.steps,
            "speed": float(speed),
            "steering_angle": float(steering),
            "track_width": float(projection.width[4]),
            "track_length": track.length,
            "waypoints": list(self._waypoints),
            "closest_waypoints": [segment, track.next_waypoint(segment)],
            "projection_distance": float(projection.distance[4]),
            "sim_time": self.sim_time,
        }
        if self.traffic.present:
            params.update(self._object_params(float(projection.distance[4])))
        return params

    def _object_params(self, car_distance: float) -> dict:
        actors = self.traffic.actors
        locations = np.array([[a.x, a.y] for a in actors])
        projection = self.track.project_points(locations)
        length = self.track.length
        ahead = (projection.distance - car_distance) % length
        return {
            "closest_objects": [int(np.argmax(ahead)), int(np.argmin(ahead))],
            "objects_location": [(float(a.x), float(a.y)) for a in actors],
            "objects_distance": [float(d) for d in projection.distance],
            "objects_distance_from_center": [float(o) for o in projection.offset],
            "objects_heading": [math.degrees(a.yaw) if a.kind == "bot" else 0.0 for a in actors],
            "objects_left_of_center": [bool(v) for v in projection.is_left],
            "objects_speed": [float(a.speed) for a in actors],
        }

    def _reward(self, params: dict) -> float:
        return checked_reward(self.reward_fn(params))

    def _info(self, status: str, params, reward: float, done: bool, action=None) -> dict:
        c = self.car
        if params is None:
            segment = int(self.track.project_points([c.position]).segment[0])
        else:
            segment = params["closest_waypoints"][0]
        if isinstance(self.actions, ContinuousActions) and action is not None:
            steering, speed = self._command(action)
            trace_action: int | str = f"[{steering:.2f} {speed:.2f}]"
        else:
            steering, speed = (0.0, 0.0) if action is None else self._command(action)
            trace_action = -1 if action is None else int(action)
        x, y = c.position
        info = {
            "params": params,
            "status": status,
            "progress": self.progress,
            "lap": self.lap,
            "sim_time": self.sim_time,
            "trace": SimTraceRow(
                episode=self._episode, steps=self.steps, X=x, Y=y, yaw=math.degrees(c.yaw),
                steer=steering, throttle=speed, action=trace_action, reward=reward, done=done,
                all_wheels_on_track=bool(params["all_wheels_on_track"]) if params else False,
                progress=self.progress, closest_waypoint=segment, track_len=self.track.length,
                tstamp=self.sim_time, episode_status=status, pause_duration=self._pause_duration,
                obstacle_crash_counter=self.counts["crashes"], wall_clock=None,
            ),
        }  # fmt: skip
        if self.mode == "evaluation":
            info.update(
                lap_times=list(self.lap_times),
                resets=self.counts["resets"],
                off_tracks=self.counts["off_tracks"],
                crashes=self.counts["crashes"],
                reversed=self.counts["reversed"],
                immobilized=self.counts["immobilized"],
            )
        return info
