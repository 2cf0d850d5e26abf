"""What people watch: a 640 x 480 colour chase view with a top-down map of the car's trail."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import cv2
import numpy as np

from simulator.camera import Lens, Mount, PerspectiveView, Solid
from simulator.config import VIEWS
from simulator.texture import preview_texture, render
from simulator.tracks import Track

if TYPE_CHECKING:
    from simulator.car import Car
    from simulator.env import DeepRacerEnv

SIZE = (640, 480)  # [px]
CHASE_MOUNT = Mount(forward=-0.9, height=0.55, pitch=22.0)  # behind and above the car
CHASE_FOV = 75.0  # [deg]
TEXTURE_PPM = 100  # [px/m] of the colour track image the chase camera projects
SKY = (236, 226, 212)  # BGR
MAP_WIDTH = 200  # [px]
TRAIL_POINTS = 900  # the last minute at 15 steps/s
TRAIL_COLOUR = (60, 60, 230)
SLIDE_COLOUR = (40, 120, 255)  # BGR: orange
TEXT_COLOUR = (255, 255, 255)
TYRE_SHADE = (30, 30, 30)  # BGR: dark on every shell colour
GLASS_SHADE = (78, 56, 40)  # BGR: tinted windows
# [m] the drawn car's roof: a 1/18 car's body and cabin, without the shell's camera mast
# (CarSpec.height, the shell's top at 0.215 m, is what the lidar and collisions meet)
DRAWN_HEIGHT = 0.12
WHEEL = (0.066, 0.034)  # [m] diameter and width of a 1/18 car's wheel
MAP_CAR_SCALE = 1.0  # [px] per unit of ``_MAP_CAR_BODY``: larger than the car at the map's scale
# The map's car in units of MAP_CAR_SCALE px, (forward, left) of its middle: nose at +9.
_MAP_CAR_BODY = np.array([(-6.0, -3.5), (2.0, -3.5), (9.0, 0.0), (2.0, 3.5), (-6.0, 3.5)])
_MAP_CAR_WHEELS = np.array(  # one short thick line per wheel
    [[(along - 1.6, side), (along + 1.6, side)] for along in (-3.5, 4.0) for side in (-4.0, 4.0)]
)
FRAME_INTERVAL = 1 / 15  # [s] between live frames: 15 per second of wall-clock time


class Spectator:
    """Renders an environment's current state for people, in BGR (OpenCV's order)."""

    def __init__(self, track: Track) -> None:
        self.track = track
        self.chase = PerspectiveView(
            render(track, pixels_per_metre=TEXTURE_PPM, colour=True),
            Lens(*SIZE, CHASE_FOV),
            CHASE_MOUNT,
            SKY,
        )
        self._map_texture = preview_texture(track, width=MAP_WIDTH)
        self._map = self._map_texture.image
        self._map_at = (SIZE[0] - self._map.shape[1] - 10, 10)

    def render(self, env: DeepRacerEnv) -> np.ndarray:
        car = env.car
        rotation, position = self.chase.pose(car.x, car.y, car.yaw)
        frame = self.chase.render_from(rotation, position)
        # Boxes and bot cars beyond the racer's car are drawn before it, those nearer after.
        x, y = car.point_ahead(car.spec.centre_offset)
        reach = math.hypot(x - position[0], y - position[1])
        beyond, nearer = [], []
        for solid in env.traffic.solids(colour=True):
            far = math.hypot(solid.x - position[0], solid.y - position[1]) >= reach
            (beyond if far else nearer).append(solid)
        self.chase.draw_solids(frame, beyond, rotation, position)
        self._draw_car(frame, car, env.car_colour, rotation, position)
        self.chase.draw_solids(frame, nearer, rotation, position)
        self._draw_map(frame, env)
        self._draw_status(frame, env)
        return frame

    def _draw_car(
        self,
        frame: np.ndarray,
        car: Car,
        colour: tuple[int, int, int],
        rotation: np.ndarray,
        position: np.ndarray,
    ) -> None:
        """The racer's 1/18 car: four dark wheels (the front ones steered), a low body and a
        cabin in the shell colour, tinted windows whose front one shows which way it faces.
        The chase camera is always above the car, so lower parts are drawn first."""
        self.chase.fill_solids(frame, car_solids(car, colour), rotation, position)
        windows, normals = car_windows(car)
        facing = np.einsum("kj,kj->k", position - windows[:, 0], normals) > 0
        self.chase.fill_polygons(frame, windows[facing], GLASS_SHADE, rotation, position)

    def _to_map(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        return np.round(self._map_texture.to_pixels(points) * 16).astype(np.int32)

    def _draw_map(self, frame: np.ndarray, env: DeepRacerEnv) -> None:
        left, top = self._map_at
        height, width = self._map.shape[:2]
        inset = self._map.copy()
        trail = env._trail[-TRAIL_POINTS:]
        if len(trail) > 1:
            cv2.polylines(inset, [self._to_map(trail)], False, TRAIL_COLOUR, 2, cv2.LINE_AA, 4)
        for actor in env.traffic.actors:
            colour = (64, 160, 232) if actor.kind == "box" else (200, 90, 40)
            centre = self._to_map([(actor.x, actor.y)])[0]
            cv2.circle(inset, tuple(centre), 4 * 16, colour, -1, cv2.LINE_AA, 4)
        self._draw_map_car(inset, env.car, env.car_colour)
        region = frame[top : top + height, left : left + width]
        cv2.addWeighted(inset, 0.9, region, 0.1, 0, dst=region)
        cv2.rectangle(frame, (left - 1, top - 1), (left + width, top + height), (90, 90, 90), 1)

    def _draw_map_car(self, inset: np.ndarray, car: Car, colour: tuple[int, int, int]) -> None:
        """The racer's car on the map: a car seen from above, nose first, with its wheels;
        boxes and bot cars are dots."""
        x, y = car.point_ahead(car.spec.centre_offset)
        centre, ahead = self._map_texture.to_pixels(
            np.array([(x, y), (x + math.cos(car.yaw), y + math.sin(car.yaw))])
        )
        forward = (ahead - centre) / np.linalg.norm(ahead - centre)
        axes = MAP_CAR_SCALE * 16 * np.array([forward, (-forward[1], forward[0])])
        wheels, body = (
            np.round(shape @ axes + centre * 16).astype(np.int32)
            for shape in (_MAP_CAR_WHEELS, _MAP_CAR_BODY)
        )
        cv2.polylines(inset, list(wheels), False, TYRE_SHADE, 3, cv2.LINE_AA, 4)
        cv2.fillConvexPoly(inset, body, colour, cv2.LINE_AA, 4)
        cv2.polylines(inset, [body], True, (255, 255, 255), 1, cv2.LINE_AA, 4)

    def _draw_status(self, frame: np.ndarray, env: DeepRacerEnv) -> None:
        text = status_line(env)
        cv2.rectangle(frame, (0, SIZE[1] - 30), (SIZE[0], SIZE[1]), (30, 30, 30), -1)
        cv2.putText(
            frame,
            text,
            (10, SIZE[1] - 10),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.55,
            TEXT_COLOUR,
            1,
            cv2.LINE_AA,
        )
        if env.car.sliding:  # the tyres at their grip: the car drifts, or spins
            slide = f"SLIDING {abs(math.degrees(env.car.slip_angle)):3.0f} deg"
            cv2.putText(
                frame,
                slide,
                (SIZE[0] - 150, SIZE[1] - 10),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.55,
                SLIDE_COLOUR,
                2,
                cv2.LINE_AA,
            )


def car_solids(car: Car, colour: tuple[int, int, int]) -> list[Solid]:
    """The racer's car as solids, lowest first: the wheels, the body, the cabin."""
    spec = car.spec
    diameter, tyre = WHEEL
    body_width = spec.width - 2 * tyre
    parts = [
        # (forward of the rear axle, left, yaw, length, width, height, shade)
        *(
            (along, side * spec.wheel_track / 2, steer, diameter, tyre, diameter, TYRE_SHADE)
            for along, steer in ((0.0, 0.0), (spec.wheelbase, car.steering))
            for side in (1, -1)
        ),
        (spec.centre_offset, 0.0, 0.0, spec.length, body_width, DRAWN_HEIGHT / 2, colour),
        (
            spec.centre_offset - 0.02,
            0.0,
            0.0,
            0.45 * spec.length,
            0.85 * body_width,
            DRAWN_HEIGHT,
            colour,
        ),
    ]
    c, s = math.cos(car.yaw), math.sin(car.yaw)
    return [
        Solid(
            car.x + along * c - side * s,
            car.y + along * s + side * c,
            car.yaw + yaw,
            length,
            width,
            height,
            shade,
        )
        for along, side, yaw, length, width, height, shade in parts
    ]


def car_windows(car: Car) -> tuple[np.ndarray, np.ndarray]:
    """The cabin's windows: their world corners (k x 4 x 3) and outward normals (k x 3). The
    rear window, the windscreen, and the windscreen's top edge on the roof, which the chase
    camera sees from behind and which marks the car's front."""
    cabin = car_solids(car, (0, 0, 0))[-1]
    c, s = math.cos(car.yaw), math.sin(car.yaw)
    forward, left, up = np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])
    middle = np.array([cabin.x, cabin.y, 0.0])
    half, wide, top = cabin.length / 2, 0.4 * cabin.width * left, cabin.height
    lift = 0.002  # [m] in front of the face it lies on
    low, tall = 0.75 * top * up, 0.15 * top * up  # a window's middle and half its height
    centres = (
        middle - (half + lift) * forward + low,
        middle + (half + lift) * forward + low,
        middle + 0.7 * half * forward + (top + lift) * up,
    )
    spans = (tall, tall, 0.3 * half * forward)
    windows = np.array(
        [
            (centre - wide - span, centre + wide - span, centre + wide + span, centre - wide + span)
            for centre, span in zip(centres, spans, strict=True)
        ]
    )
    return windows, np.array([-forward, forward, up])


def status_line(env: DeepRacerEnv) -> str:
    """The frame's status bar: the lap of an evaluation, the progress, the speed and the time.
    A training episode is not numbered here: each car counts its own episodes, several cars
    drive on a worker, so no number of theirs is the job's; the page counts the job's episodes,
    from the same state as its iterations (``training.selectors.training_status``)."""
    text = f"{env.progress:5.1f}%   {env.car.speed:4.2f} m/s   {env.sim_time:6.2f} s"
    return f"Lap {env.lap}/{env.laps}   {text}" if env.mode == "evaluation" else text


def view_image(env: DeepRacerEnv, view: str, observation: dict | None = None) -> np.ndarray:
    """What a viewer sees of ``env``: ``"spectator"`` (the chase view with its map, BGR) or
    ``"camera"`` (what the policy sees: the 160 x 120 grayscale camera, the left one of a stereo
    pair), from ``observation`` when given, else rendered now."""
    if view == "spectator":
        return env.spectator.render(env)
    if view not in VIEWS:
        raise ValueError(f"no view named {view!r}")
    if observation is None:
        observation = env._observe()
    return observation[env.camera_name][0]


def jpeg(image: np.ndarray, quality: int = 80) -> bytes:
    ok, data = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, quality])
    if not ok:
        raise ValueError("the image could not be encoded as JPEG")
    return data.tobytes()
