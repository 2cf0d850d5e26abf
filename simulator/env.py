"""The DeepRacer environment: ``gymnasium.make("Pitlane/DeepRacer-v0", ...)``.

Long because it is DeepRacer's environment as one Gymnasium class, as Gymnasium's own are:
reset and step, the reward params, the episode statuses and resets, the trace and the render
hooks. What it is made of lives apart: the car (``car``), the tracks, the PyBullet world
(``world``), the sensors (``camera``, ``lidar``) and the spectator.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import cv2
import gymnasium as gym
import numpy as np
from gymnasium import spaces

from simulator import config
from simulator.actors import Traffic
from simulator.camera import (
    LENSES,
    SIMAPP_FOV,
    STEREO_BASELINE,
    Lens,
    Mount,
    PerspectiveView,
    deepracer_mount,
)
from simulator.car import Car, CarSpec, lidar_mount
from simulator.config import ContinuousActions, DiscreteActions
from simulator.head_to_head import grid_place
from simulator.params import heading, object_param_defaults, prev_next, waypoint_distances
from simulator.randomisation import Scene
from simulator.rewards import checked_reward, follow_centre_line
from simulator.room import room_for
from simulator.texture import render, style_for
from simulator.trace import SimTraceRow
from simulator.tracks import Track, driven
from simulator.world import World


def default_config(camera_lens: str = "simulator") -> dict[str, Any]:
    """The physical constants of the simulation, with their units, for a camera lens of
    ``simulator.camera.LENSES``."""
    return {
        "control_hz": config.CONTROL_HZ,  # [Hz] one step is 1/15 s
        "physics_substeps": 8,  # per control step (120 Hz integration)
        # Per episode, the prepare step included, then time_up. DeepRacer's cap is 100,000
        # (simapp environments/deepracer_racetrack_env.py:33,182-184, 01f5f01); ours stays at
        # 10,000 (11 simulated minutes): an evaluation of a car that never finishes would
        # otherwise record two hours of video.
        "max_steps": 10_000,
        "start_advance": 0.05,  # [fraction of the lap] the training start moves per episode
        "stall_steps": 15,  # consecutive steps that make reversed or immobilized
        "immobilized_distance": 0.0003,  # [m] moved per step under which the car is stuck
        "camera_size": (160, 120),  # [px] width, height: simapp environments/constants.py:21
        # simapp's camera (simulator.camera cites each number): 1.13 rad across, or the car's
        # wide lens with camera_lens="wide"; the lens 0.227 m ahead of the rear axle, 0.127 m
        # above the ground, pitched 15° down, from the URDF's joint chain.
        "camera_fov": LENSES[config.choice("The camera lens", camera_lens, LENSES)],  # [deg]
        "camera_mount": deepracer_mount(),  # forward [m], height [m], pitch down [deg]
        "stereo_baseline": STEREO_BASELINE,  # [m] between the stereo cameras
        # [px/m] of the track image the camera projects: 4 px across the 1 in centre line, and
        # about one per camera pixel at the foot of the picture (2.4 mm of ground)
        "camera_texture_ppm": 160,
        # what the camera sees round the field and above it (a simulator.camera.Room); None:
        # the track's DeepRacer world's, read from its meshes (walls 1 m high round Pitlane's)
        "room": None,
        "track_style": None,  # a texture.Style for the track image; None: simapp's for the track
        # simapp launch/racecar.launch.py:37-45, sensors/constants.py:20-28 (01f5f01): 64 rays
        # over ±150° of the laser's own heading; LIDAR is clipped to 0.15-1.0 m
        # (sensors/utils.py:56-57). The laser faces backwards (simulator.car.LIDAR_JOINT): its
        # first ray points 30° left of the car's heading and they sweep round behind the car to
        # 30° right, blind 30° either side of straight ahead, where the camera looks.
        "lidar_rays": 64,
        "lidar_fov": 300.0,  # [deg] ±150
        "lidar_heading": 180.0,  # [deg] the laser's, from the car's
        "lidar_range": (0.15, 1.0),  # [m] after clipping
        "lidar_mount": lidar_mount(),  # [m] forward of the rear axle, above the ground
        # SECTOR_LIDAR: 8 sectors of 8 consecutive rays, 1 when the nearest return in the sector
        # is under 0.5 m. simapp environments/constants.py:27,29 and
        # filters/observation/observation_sector_discretize_filter.py:53-71 (01f5f01).
        "sector_lidar_sectors": 8,
        "sector_lidar_clipping": 0.5,  # [m]
        # Gazebo's noise, where ``noise`` asks for it (an evaluation's trials). The lidar's rays:
        # Gaussian, mean 0, deviation 0.01 m (simapp urdf/deepracer/racecar.xacro:26-27,
        # racecar.gazebo:156-159, 01f5f01); its cameras have no <noise> (racecar.gazebo:58-132).
        "lidar_noise": 0.01,  # [m] standard deviation
        # A step's action takes hold late: simapp pauses the physics only once a step's image has
        # come, so it runs on with the old action until the pause lands, "the step duration won't
        # be exactly same" (environments/deepracer_racetrack_env.py:157-177). Up to 9 of
        # Gazebo's 1 ms physics steps, drawn evenly: a DeepRacer evaluation's steps last 66.7 ms
        # with a deviation of 3.2-4.2 ms (deepracer-utils' sample console evaluation,
        # tests/deepracer/logs/sample-console-logs/sim-trace/evaluation/20220612082523-*,
        # three trials), as the difference of two such delays has (4.1 ms).
        "command_latency": 9,  # [physics steps of 1 ms] the most an action waits
    }


TERMINAL = ("off_track", "crashed", "reversed", "immobilized", "lap_complete")


class _Advanced(NamedTuple):
    """A step ``advance`` began and ``conclude`` ends: its action, status and reward params
    (None for a penalty's pause, which has none)."""

    action: Any
    status: str
    params: dict | None


class DeepRacerEnv(gym.Env):
    """A 1/18-scale car on a DeepRacer track, seen through its sensors, rewarded by a racer's
    reward function.

    **Actions**: with a discrete action space, ``Discrete(n)``: the index of an action of the
    ``model_metadata.json`` list. With a continuous one, ``Box(-1, 1, (2,), float32)``: steering
    and speed, each scaled linearly onto its [low, high] range (and clipped there).

    **Observations**: a ``Dict`` keyed by sensor name. ``FRONT_FACING_CAMERA``: ``uint8`` (1, 120,
    160), grayscale; ``STEREO_CAMERAS``: (2, 120, 160), left then right; ``LIDAR``: ``float32``
    (64,), metres over ±150° (left is positive), clipped to 0.15-1.0; ``SECTOR_LIDAR``:
    ``MultiBinary(8)``, each sector of 8 rays 1 when something is within 0.5 m.

    **Reward**: ``reward_fn(params)``, where ``params`` is the dict of DeepRacer's reward-function
    input (docs/reward-functions.md, docs/coming-from-deepracer.md). It must return a finite
    real number within ±1e5.

    **Steps and clock**: as DeepRacer counts them, ``reset()`` is the episode's prepare step
    (step 1, trace status ``prepare``, reward function not called) and the first ``step()`` is
    step 2. ``clock`` is the simulation clock of this environment: it runs on through resets
    (a reset with a seed starts the run over, the clock included).

    **Starting state**: the car at rest on the centre line, heading along the track. In training
    the start advances ``start_advance`` of the lap every episode, beginning at ``start``; in
    evaluation every episode starts at ``start`` (0: the start line).

    **Episode end**: training ends on any terminal status (off_track, crashed, reversed,
    immobilized, lap_complete), evaluation after ``laps`` laps; both truncate at ``max_steps``
    (time_up). In evaluation, going off track or crashing freezes the car for the penalty while the
    clock runs (status ``pause``) and then puts it back on the centre line at its last progress;
    reversing or being immobilized puts it back without a penalty. Lap times include penalties.
    With ``max_resets``, the episode ends (terminated, with the status that would have reset it)
    when the car would be put back more than ``max_resets`` times: 0 ends it at the first, as
    DeepRacer's evaluation does with NUMBER_OF_RESETS (simapp rollout_agent_ctrl.py:1042-1053,
    its count cleared per episode at :1076, 01f5f01); None puts it back for ever.

    **Arguments**: ``track`` (a built-in name or a DeepRacer ``.npy`` path), ``route`` (one of
    the track's DeepRacer route files by WORLD_NAME, driven as simapp drives it:
    ``Track.on_route``; None: the file the console drives ``direction``), ``direction``,
    ``sensors``, ``action_space``, ``race_type``, ``objects`` ({count, randomize}), ``bots``
    ({count, speed, lane_changes}), ``mode``, ``laps``, ``penalties`` ({off_track, crash} in
    seconds), ``max_resets``, ``start`` (fraction of the lap), ``reward_fn``, ``seed``,
    ``noise`` (Gazebo's, drawn from the episode's seed: the lidar's and each action's delay;
    off, the same actions give the same episode), ``render_mode`` ("rgb_array": the 640 x 480
    spectator view), ``car`` (a ``CarSpec``),
    ``car_colour`` (BGR), ``camera_lens`` ("simulator": DeepRacer's simulated camera, 64.7°
    across; "wide": the physical car's 120° lens), ``randomise`` (domain randomisation: each
    episode's light, colours, textures, camera noise, blur and mount, and the car's grip, drawn
    from the episode's seed; ``simulator.randomisation``).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    # Long because its signature is Gymnasium's keyword arguments, one a line, each checked here.
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
        max_resets: int | None = None,
        start: float = 0.0,
        reward_fn: Callable[[dict], float] | None = None,
        seed: int | None = None,
        noise: bool = False,
        render_mode: str | None = None,
        car: CarSpec | None = None,
        car_colour: tuple[int, int, int] = (40, 40, 220),
        camera_lens: str = "simulator",
        randomise: bool = False,
        route: str | None = None,
        rivals: int = 0,
        rival_colours: Sequence[tuple[int, int, int]] = (),
        grid: int | None = None,
    ) -> None:
        self.config = default_config(camera_lens)
        self.track: Track = driven(
            track,
            config.choice("The direction", direction, ("counterclockwise", "clockwise")),
            route,
        )
        self.camera_name, self.lidar_name = config.sensors(sensors)
        self.actions = config.action_space(action_space)
        self.race_type = config.choice("The race type", race_type, config.RACE_TYPES)
        if race_type == "OBJECT_AVOIDANCE" and objects is None:
            objects = {}
        if race_type == "HEAD_TO_BOT" and bots is None:
            bots = {}
        self.traffic = Traffic(
            self.track,
            config.objects(objects, race_type),
            config.bots(bots, race_type),
            rivals=config.positive_int("The number of rivals", rivals, 0, config.MAX_CARS - 1),
            rival_shades=tuple(_shade(colour) for colour in rival_colours),
        )
        # [m] along the track from the start, left of the centre line: the centre line's start
        # alone, or place ``grid`` (0 first) on simapp's grid of a race of several cars
        if grid is not None:
            grid = config.positive_int("The place on the grid", grid, 0, config.MAX_CARS - 1)
        self.grid = (0.0, 0.0) if grid is None else grid_place(self.track, grid)
        self.mode = config.choice("The mode", mode, config.MODES)
        self.laps = config.positive_int("The number of laps", laps, 1, 100)
        self.penalties = config.penalties(penalties)
        self.max_resets = config.resets(max_resets)
        self.start = config.fraction("The start", start)
        self.reward_fn = reward_fn or follow_centre_line
        self.noise = bool(noise)
        self.render_mode = config.choice("The render mode", render_mode, (None, "rgb_array"))
        self.car_colour = tuple(int(channel) for channel in car_colour)  # JSON gives a list

        self.car = Car(car, substeps=self.config["physics_substeps"])
        self.dt = 1.0 / self.config["control_hz"]
        self._build_spaces()
        self._build_sensors()
        self._scene = Scene(self._cameras, self.car.spec, self._sky) if randomise else None
        self._world = self._build_world()
        self._actor_bodies = []
        self._waypoints = tuple(self.track.waypoints)
        self._waypoint_distances = waypoint_distances(self.track)
        self._spectator = None
        self._episode = -1
        self._ghost = self._into_rival = False  # (reset sets them each episode)
        self._seed = seed
        # The worker's simulation clock [s]: it runs on through resets and never backwards, as
        # Gazebo's clock does in simapp (rollout_agent_ctrl.py:245, 01f5f01). The trace's tstamp and
        # params["sim_time"] read it; deepracer-utils sums its differences (log_utils.py:349).
        self.clock = 0.0

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
        if self._scene is not None:  # domain randomisation: this episode's look, from its seed
            self._cameras, self.car.spec, self.look = self._scene.draw(self.np_random)
        self._sync_actor_bodies()
        self._place_car(start + self.grid[0], self.grid[1])
        # The reset is DeepRacer's prepare step: step 1 of the episode, the car held at its start,
        # reward 0 and the reward function not called; so the first step() is step 2 and the first
        # reward call sees steps == 2.0. simapp rollout_agent_ctrl.py:180,643,779-780,1079-1086
        # (01f5f01). ``sim_time`` is the episode's time, 0 at the prepare row.
        self.steps = 1
        if seed is not None:
            self.clock = 0.0  # a seed starts the run over, clock included (Gymnasium's contract)
        self.clock += self.dt
        self.sim_time = 0.0
        self.lap = 1
        self._lap_finished = False
        self.status = "prepare"
        self.lap_times: list[float] = []
        self._lap_started = 0.0
        self._travelled = min(self.grid[0], 0.0)  # a car on the grid behind the line starts short
        self.progress = 0.0
        self._falling = self._stuck = 0
        self._pause_left = 0
        self._ghost = self._into_rival = False
        self._pause_duration = 0.0
        self._resume_at, self._resume_travelled = self._distance, self._travelled
        self.counts = dict.fromkeys(
            ("off_tracks", "crashes", "reversed", "immobilized", "resets"), 0
        )
        self._trail = [self.car.position]
        self._held = (0.0, 0.0)  # the commands (steering, speed) the car drives by: at rest
        self._last_params: dict | None = None
        self._pending: _Advanced | None = None  # the step advance() began, until concluded
        return self._observe(), self._info("prepare", None, 0.0, False)

    def step(self, action):
        params = self.advance(action)
        return self.conclude(None if params is None else self.reward_fn(params))

    def advance(self, action) -> dict | None:
        """A step up to its reward: the clock, the car's and the traffic's motion, the status,
        and the reward function's ``params`` returned (None for a step that calls no reward
        function: a penalty's pause). ``conclude`` with the reward ends the step. ``step`` is
        the two with the reward function between them; a fleet of cars advances every car,
        asks the racer's code for their rewards in one call, then concludes each
        (``rl.episode.Fleet``), and drives the same episodes."""
        self.steps += 1
        self.clock += self.dt
        self.sim_time = (self.steps - 1) * self.dt
        if self._lap_finished:
            self.lap += 1
            self._lap_finished = False
        if self._pause_left > 0:
            self._pending = _Advanced(action, "pause", None)
            return None
        steering, speed = self._command(action)
        moved = self._drive(steering, speed)
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
        self._pending = _Advanced(action, status, params)
        return params

    def conclude(self, reward: float | None):
        """End the step ``advance`` began, with ``reward``: the reward function's value for the
        params it returned (``RewardError`` if it is not a reward), ignored for a step that had
        none. Gymnasium's (observation, reward, terminated, truncated, info), as ``step``."""
        advanced, self._pending = self._pending, None
        if advanced is None:
            raise RuntimeError("conclude() ends a step that advance() began.")
        action, status, params = advanced
        if params is None:
            return self._paused_step()
        reward = checked_reward(reward)
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
        if self._world is not None:
            self._world.close()

    def connect_world(self) -> None:
        """Connect the collision world, where there is one, to PyBullet now (``World.connect``):
        a sandbox child does before it seals. ``WorldUnavailable`` where PyBullet is missing."""
        if self._world is not None:
            self._world.connect()

    # Motion and statuses

    def _command(self, action) -> tuple[float, float]:
        if isinstance(self.actions, DiscreteActions):
            return self.actions.actions[int(action)]
        return self.actions.scale(np.asarray(action, dtype=np.float64))

    def _drive(self, steering: float, speed: float) -> float:
        """Drive one step toward the commands; the distance moved [m]. With ``noise``, the
        commands before hold for the first 0-``command_latency`` physics steps of it."""
        held, self._held = self._held, (steering, speed)
        if not self.noise:
            return self.car.step(speed, steering, self.dt)
        ticks = int(self.np_random.integers(0, self.config["command_latency"] + 1))
        late = ticks * self.car.spec.control_period
        moved = self.car.step(held[1], held[0], late) if ticks else 0.0
        return moved + self.car.step(speed, steering, self.dt - late)

    def _place_car(self, distance: float, left: float = 0.0) -> None:
        """Put the car at rest so that its reported position is at ``distance``, ``left`` of the
        centre line."""
        x, y, heading = self.track.point_at(distance % self.track.length, left)
        back = self.car.spec.report_offset
        self.car.place(
            float(x) - back * math.cos(heading), float(y) - back * math.sin(heading), float(heading)
        )
        self._sync_car_body()
        self._distance = float(self.track.project_points([self.car.position]).distance[0])

    def _sync_car_body(self) -> None:
        if self._world is None:
            return
        self._world.place(self._car_body, *self.body_pose)

    def _sync_actor_bodies(self) -> None:
        actors = self.traffic.actors
        while len(self._actor_bodies) < len(actors):
            actor = actors[len(self._actor_bodies)]
            self._actor_bodies.append(
                self._world.add_obstacle(actor.length, actor.width, actor.height)
            )
        for body, actor in zip(self._actor_bodies, actors, strict=False):
            self._world.place(body, actor.x, actor.y, actor.yaw)

    def place_rivals(self, poses, ghosts=None) -> None:
        """Where the other racers' cars stand now, (x, y, yaw) of each (``rivals`` of them): the
        camera and lidar see them and the car crashes into them, as into bot cars, unless they
        are ``ghosts`` (serving a crash's penalty, ``ghost``)."""
        self.traffic.place_rivals(poses, ghosts)
        self._sync_actor_bodies()

    @property
    def ghost(self) -> bool:
        """Whether the car is a ghost: since it crashed into a rival, it has served its penalty
        where it stood, out of the collisions (as simapp's crashed car, blinking, leaves the
        collision list: rollout_agent_ctrl.py:897-915, 01f5f01), and has not yet come clear of
        the cars it touched. It crashes into no rival and no rival into it meanwhile."""
        return self._ghost

    @property
    def body_pose(self) -> tuple[float, float, float]:
        """The middle of the car's body and its heading: where a rival's camera sees it."""
        c = self.car
        x, y = c.point_ahead(c.spec.centre_offset)
        return float(x), float(y), float(c.yaw)

    def _crashed(self) -> bool:
        """Whether the car touches a box, a bot car or a rival's car (``_into_rival``: only a
        rival's); a ghost touches no rival, nor any rival a ghost."""
        self._into_rival = False
        if not self.traffic.present:
            return False
        self._sync_car_body()
        touched = set(self._world.car_touches())
        hit = [
            a
            for a, body in zip(self.traffic.actors, self._actor_bodies, strict=False)
            if body in touched
        ]
        rivals = [actor for actor in hit if actor.kind == "rival"]
        if self._ghost and self._pause_left == 0 and not rivals:
            self._ghost = False  # clear of the cars: it races again
        solid = [a for a in hit if a.kind != "rival" or not (a.ghost or self._ghost)]
        self._into_rival = bool(solid) and all(actor.kind == "rival" for actor in solid)
        return bool(solid)

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
            if self._out_of_resets():
                return True, False
            seconds = self.penalties.off_track if status == "off_track" else self.penalties.crash
            self._pause_left = round(seconds / self.dt)
            # into a rival's car: the penalty served where it stands, as a ghost (``ghost``)
            self._ghost = status == "crashed" and self._into_rival
            if self._pause_left == 0 and not self._ghost:
                self._put_back()
        elif status in ("reversed", "immobilized"):
            self.counts[status] += 1
            if self._out_of_resets():
                return True, False
            self._put_back()
        return False, truncated

    def _out_of_resets(self) -> bool:
        """Whether the episode has used the resets ``max_resets`` allows."""
        return self.max_resets is not None and self.counts["resets"] >= self.max_resets

    def _paused_step(self):
        """A step frozen by a penalty: the clock runs, the car waits, then goes back on track."""
        self._pause_left -= 1
        self._pause_duration += self.dt
        if self._pause_left == 0 and not self._ghost:
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
        style = cfg["track_style"] or style_for(self.track)
        room = cfg["room"] or room_for(self.track, style)
        texture = render(
            self.track, pixels_per_metre=cfg["camera_texture_ppm"], style=style, field=room.field
        )
        lens = Lens(*cfg["camera_size"], cfg["camera_fov"])
        forward, height, pitch = cfg["camera_mount"]
        if self.camera_name == "STEREO_CAMERAS":
            half = cfg["stereo_baseline"] / 2
            lefts = (half, -half)
        else:
            lefts = (0.0,)
        self._sky = room.sky
        self._cameras = [
            PerspectiveView(texture, lens, Mount(forward, height, pitch, left), room.sky, room)
            for left in lefts
        ]
        half = cfg["lidar_fov"] / 2
        angles = np.radians(cfg["lidar_heading"] + np.linspace(-half, half, cfg["lidar_rays"]))
        self._lidar_angles = angles

    def _build_world(self) -> World | None:
        """A PyBullet world holding the car's body, only where something stands on the track to
        be hit or seen (boxes, bot cars): without one the lidar's rays reach their range, and a
        time trial runs where PyBullet is not installed."""
        if not self.traffic.present:
            return None
        world = World()
        spec = self.car.spec
        self._car_body = world.add_car(spec.length, spec.width, spec.height)
        return world

    def _observe(self) -> dict[str, np.ndarray]:
        c = self.car
        solids = self.traffic.solids() if self.traffic.present else ()
        frames = [camera.render(c.x, c.y, c.yaw, solids) for camera in self._cameras]
        observation = {self.camera_name: np.stack(frames)}
        if self.lidar_name is not None:
            distances = self._lidar()
            if self.noise:
                distances = self._noisy(distances)
            if self.lidar_name == "LIDAR":
                observation["LIDAR"] = distances.astype(np.float32)
            else:
                observation["SECTOR_LIDAR"] = self._sectors(distances)
        return observation

    def _sectors(self, distances: np.ndarray) -> np.ndarray:
        """SECTOR_LIDAR from the 64 distances: in ray order from -150°, 8 groups of 8 rays, each
        1 when its nearest return is under the clipping distance (0.5 m)."""
        sectors = distances.reshape(self.config["sector_lidar_sectors"], -1).min(axis=1)
        return (sectors < self.config["sector_lidar_clipping"]).astype(np.int8)

    def _noisy(self, distances: np.ndarray) -> np.ndarray:
        """The rays that hit something within our range (lidar_range: Gazebo's reaches 6 m,
        simapp racecar.xacro:24, we clip at ours), with the lidar's noise, clipped again; a ray
        that reaches the range saw nothing, and is left so."""
        low, high = self.config["lidar_range"]
        noise = self.np_random.normal(0.0, self.config["lidar_noise"], distances.shape)
        return np.where(distances < high, np.clip(distances + noise, low, high), distances)

    def _lidar(self) -> np.ndarray:
        low, high = self.config["lidar_range"]
        if self._world is None:  # nothing on the track: every ray reaches its range
            return np.full(len(self._lidar_angles), high)
        c = self.car
        angles = c.yaw + self._lidar_angles
        directions = np.column_stack([np.cos(angles), np.sin(angles)])
        forward, height = self.config["lidar_mount"]
        origin = (*c.point_ahead(forward), height)
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
        distance = float(projection.distance[4])
        params = {
            "all_wheels_on_track": bool(on_track.all()),
            "x": x,
            "y": y,
            "heading": heading(math.degrees(c.yaw)),
            "distance_from_center": float(projection.offset[4]),
            "is_left_of_center": bool(projection.is_left[4]),
            "is_offtrack": status == "off_track",
            "is_crashed": crashed,
            # The route driven against its file's order (simapp agent_ctrl/utils.py:101 reads
            # REVERSE_DIR; a console "clockwise" world is its own file and reads False).
            "is_reversed": track.reversed,
            "progress": self.progress,
            "steps": float(self.steps),  # a float in DeepRacer (rollout_agent_ctrl.py:180, 643)
            "speed": float(speed),
            "steering_angle": float(steering),
            "track_width": float(projection.width[4]),
            "track_length": track.length,
            "waypoints": list(self._waypoints),
            "closest_waypoints": list(self._closest_waypoints(distance)),
            "projection_distance": distance,
            # The simulation clock, not reset per episode: simapp rollout_agent_ctrl.py:245,652.
            "sim_time": self.clock,
            **object_param_defaults(),
        }
        if self.traffic.actors:
            params.update(self._object_params(distance))
        return params

    def _closest_waypoints(self, distance: float) -> tuple[int, int]:
        """DeepRacer's [behind, ahead] waypoint indices for a point projected ``distance`` along
        the centre line: the next index is the first waypoint whose distance is greater, so a
        point exactly on waypoint i gives [i, i + 1], and the loop's last segment gives
        [N - 2, N - 1] (the repeated closing point, no wrap to 0). simapp
        track_geom/track_data.py:47-48 (ndists) and track_geom/utils.py:140-147 (find_prev_next),
        agent_ctrl/utils.py:76-77 (01f5f01)."""
        return prev_next(self._waypoint_distances, distance)

    def _object_params(self, car_distance: float) -> dict:
        """The objects_* params as simapp track_geom/track_data.py:372-441 (01f5f01) makes them:
        objects in the order they were placed, distances along the centre line from waypoint 0
        (not sorted), [behind, ahead] by that distance with find_prev_next's rule, and headings
        (radians) and speeds only when there are bot cars, 0.0 for every object otherwise."""
        actors = self.traffic.actors
        locations = np.array([[a.x, a.y] for a in actors])
        projection = self.track.project_points(locations)
        order = np.argsort(projection.distance, kind="stable")
        behind, ahead = prev_next(projection.distance[order].tolist(), car_distance)
        bots = self.traffic.bots
        return {
            "closest_objects": [int(order[behind]), int(order[ahead])],
            "objects_location": [[float(a.x), float(a.y)] for a in actors],
            "objects_distance": [float(d) for d in projection.distance],
            "objects_distance_from_center": [float(o) for o in projection.offset],
            "objects_heading": [float(a.yaw) if bots else 0.0 for a in actors],
            "objects_left_of_center": [bool(v) for v in projection.is_left],
            "objects_speed": [float(bots.speed) if bots else 0.0 for _ in actors],
            "object_in_camera": self._in_camera(actors[int(order[ahead])]),
        }

    def _in_camera(self, actor) -> bool:
        """Whether the object is in the front camera's view: its centre or a corner of its
        footprint lies within 1.13 rad across, at least 0.2 m ahead of the camera. simapp
        track_geom/track_data.py:554-590 and cameras/frustum.py:41-43,117-122 (near plane 0.2 m;
        the far plane, 300 m, is beyond any track; 1.13 rad hard-coded whatever the camera, so
        the reward param is DeepRacer's with the wide lens too) (01f5f01)."""
        c = self.car
        forward, _height, _pitch = self.config["camera_mount"]
        cx, cy = c.point_ahead(forward)
        cos_a, sin_a = math.cos(actor.yaw), math.sin(actor.yaw)
        half_l, half_w = actor.length / 2, actor.width / 2
        points = [(actor.x, actor.y)] + [
            (
                actor.x + u * half_l * cos_a - v * half_w * sin_a,
                actor.y + u * half_l * sin_a + v * half_w * cos_a,
            )
            for u in (-1, 1)
            for v in (-1, 1)
        ]
        half_fov = math.radians(SIMAPP_FOV) / 2
        cos_y, sin_y = math.cos(c.yaw), math.sin(c.yaw)
        for x, y in points:
            along = (x - cx) * cos_y + (y - cy) * sin_y
            across = -(x - cx) * sin_y + (y - cy) * cos_y
            if along >= 0.2 and abs(across) <= along * math.tan(half_fov):
                return True
        return False

    def _wheels_on_track(self, params: dict | None) -> bool:
        """all_wheels_on_track for the trace: the params' value, or the wheels' where there are no
        params (the prepare and pause rows; DeepRacer computes it on every row)."""
        if params is not None:
            return bool(params["all_wheels_on_track"])
        wheels = self.track.project_points(self.car.wheels())
        return bool((wheels.offset <= wheels.half_width).all())

    def _info(self, status: str, params, reward: float, done: bool, action=None) -> dict:
        c = self.car
        x, y = c.position
        if params is None:
            distance = float(self.track.project_points([(x, y)]).distance[0])
            behind, ahead = self._closest_waypoints(distance)
        else:
            behind, ahead = params["closest_waypoints"]
        # The trace's closest_waypoint is the nearer of the two, a tie going to the one behind:
        # simapp bundle/markov/agent_ctrl/utils.py:124-125 (01f5f01).
        (bx, by), (ax, ay) = self._waypoints[behind], self._waypoints[ahead]
        nearest = ahead if math.hypot(ax - x, ay - y) < math.hypot(bx - x, by - y) else behind
        # The prepare row has no action yet: -1, or [0.00 0.00] for a continuous action space.
        steering, speed = (0.0, 0.0) if action is None else self._command(action)
        if isinstance(self.actions, ContinuousActions):
            trace_action: int | str = f"[{steering:.2f} {speed:.2f}]"
        else:
            trace_action = -1 if action is None else int(action)
        info = {
            "params": params,
            "status": status,
            "progress": self.progress,
            "lap": self.lap,
            "sim_time": self.sim_time,
            "trace": SimTraceRow(
                episode=self._episode,
                steps=float(self.steps),
                X=x,
                Y=y,
                yaw=math.degrees(c.yaw),
                steer=steering,
                throttle=speed,
                action=trace_action,
                reward=reward,
                done=done,
                all_wheels_on_track=self._wheels_on_track(params),
                progress=self.progress,
                closest_waypoint=nearest,
                track_len=self.track.length,
                tstamp=self.clock,
                episode_status=status,
                pause_duration=self._pause_duration,
                obstacle_crash_counter=self.counts["crashes"],
                wall_clock=None,
            ),
        }
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


def _shade(bgr: Sequence[int]) -> tuple[int, tuple[int, int, int]]:
    """A car's colour as the cameras draw it: (gray level, BGR)."""
    blue, green, red = (int(channel) for channel in bgr)
    return round(0.2989 * red + 0.5870 * green + 0.1140 * blue), (blue, green, red)
