"""What people watch: a 640 x 480 colour chase view with a top-down map of the car's trail."""

from __future__ import annotations

from typing import TYPE_CHECKING

import cv2
import numpy as np

from simulator.camera import Lens, Mount, PerspectiveView, Solid
from simulator.texture import preview_texture, render
from simulator.tracks import Track

if TYPE_CHECKING:
    from simulator.env import DeepRacerEnv

SIZE = (640, 480)  # [px]
CHASE_MOUNT = Mount(forward=-0.9, height=0.55, pitch=22.0)  # behind and above the car
CHASE_FOV = 75.0  # [deg]
TEXTURE_PPM = 100  # [px/m] of the colour track image the chase camera projects
SKY = (236, 226, 212)  # BGR
MAP_WIDTH = 200  # [px]
TRAIL_POINTS = 900  # the last minute at 15 steps/s
TRAIL_COLOUR = (60, 60, 230)
TEXT_COLOUR = (255, 255, 255)
VIEWS = ("spectator", "camera")  # what a live viewer can watch (see ``view_image``)
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
        spec = car.spec
        solids = env.traffic.solids(colour=True)
        x, y = car.point_ahead(spec.centre_offset)
        solids.append(Solid(x, y, car.yaw, spec.length, spec.width, spec.height, env.car_colour))
        frame = self.chase.render(car.x, car.y, car.yaw, solids)
        self._draw_map(frame, env)
        self._draw_status(frame, env)
        return frame

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
        centre = self._to_map([env.car.position])[0]
        cv2.circle(inset, tuple(centre), 5 * 16, env.car_colour, -1, cv2.LINE_AA, 4)
        cv2.circle(inset, tuple(centre), 5 * 16, (255, 255, 255), 1, cv2.LINE_AA, 4)
        region = frame[top : top + height, left : left + width]
        cv2.addWeighted(inset, 0.9, region, 0.1, 0, dst=region)
        cv2.rectangle(frame, (left - 1, top - 1), (left + width, top + height), (90, 90, 90), 1)

    def _draw_status(self, frame: np.ndarray, env: DeepRacerEnv) -> None:
        laps = (
            f"Lap {env.lap}/{env.laps}" if env.mode == "evaluation" else f"Episode {env._episode}"
        )
        text = f"{laps}   {env.progress:5.1f}%   {env.car.speed:4.2f} m/s   {env.sim_time:6.2f} s"
        cv2.rectangle(frame, (0, SIZE[1] - 30), (SIZE[0], SIZE[1]), (30, 30, 30), -1)
        cv2.putText(frame, text, (10, SIZE[1] - 10), cv2.FONT_HERSHEY_SIMPLEX, 0.55,
                    TEXT_COLOUR, 1, cv2.LINE_AA)  # fmt: skip


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
