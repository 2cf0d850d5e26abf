"""Cameras that see the flat track by projecting its top-down image, and solids drawn on top.

A camera mounted on the car sees the ground plane through a homography: one OpenCV perspective
warp of the pre-drawn track image gives the whole picture, thousands of times a second, where
rendering 3D geometry would manage a few hundred. Above the horizon there is the room: the walls
round the field and the background over them (``Room``). Boxes and cars are solids: their faces
are projected and filled, farthest first.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from simulator.room import Room
from simulator.texture import TrackTexture

NEAR = 0.01  # [m] faces nearer than this to the camera plane are clipped
DRAW_DISTANCE = 12.0  # [m] beyond which a solid is smaller than a pixel

# DeepRacer's simulated camera (simapp at 01f5f01; the same numbers at 2fc2d75c, the ROS 1
# simulator the console ran): Gazebo renders 640 x 480 pixels 1.13 rad across
# (bundle/urdf/deepracer/racecar.gazebo:67-70), which the agent resizes to 160 x 120
# (bundle/markov/sensors/sensors_rollout.py:174, environments/constants.py:21), so the 160 x 120
# picture keeps the 1.13 rad. Its object-in-camera frustum uses the same angle
# (bundle/markov/cameras/frustum.py:43).
SIMAPP_FOV = math.degrees(1.13)  # [deg] horizontal: 64.7
# The physical car's lens, for racers matching their own car: 120 degrees across, as DeepRacer's
# console described the car's camera in its garage. The car's camera package
# (aws-deepracer-camera-pkg, camera_pkg/src/camera_node.cpp:29-30,153-154) only resizes the
# frames to 160 x 120 and publishes no field of view, so the 120 degrees is the console's word;
# the lens's barrel distortion is not modelled (a pinhole of the same width).
CAR_FOV = 120.0  # [deg]
LENSES = {"simulator": SIMAPP_FOV, "wide": CAR_FOV}  # a model's camera_lens -> horizontal fov

# Where the lens sits: the joint chain of bundle/urdf/deepracer/deepracer_single_cam.urdf
# (01f5f01): base_link -> chassis (base_link_joint, :41, in simulator.car), -> zed_camera_link
# (zed_camera_joint, :413-415), pitched down, -> camera_link, the lens Gazebo renders from
# (camera_joint, :516-517, in zed_camera_link's pitched frame).
ZED_CAMERA_JOINT = (0.091711, 0.080023)  # [m] forward, up in the chassis frame: :414
CAMERA_PITCH = 0.2618  # [rad] down (URDF pitch about y; a positive one tips x down): :415
CAMERA_JOINT = (0.044755, 0.04)  # [m] forward, up in zed_camera_link's frame: :517
# The stereo pair: zed_camera_joint_leftcam at y +0.03, _rightcam at -0.03, otherwise the single
# camera's chain (deepracer_stereo_cam.urdf:398, :511, :453, :566).
STEREO_BASELINE = 0.06  # [m]


def deepracer_mount() -> tuple[float, float, float]:
    """simapp's lens as (forward of our car's origin, the middle of the rear axle [m]; height
    above the ground [m]; pitch down [deg]): 0.227 m, 0.127 m, 15 degrees."""
    from simulator.car import CHASSIS_Z, REAR_AXLE_X, REAR_AXLE_Z, CarSpec

    c, s = math.cos(CAMERA_PITCH), math.sin(CAMERA_PITCH)
    forward = ZED_CAMERA_JOINT[0] + CAMERA_JOINT[0] * c + CAMERA_JOINT[1] * s  # of base_link
    up = ZED_CAMERA_JOINT[1] - CAMERA_JOINT[0] * s + CAMERA_JOINT[1] * c  # above the chassis
    ground = REAR_AXLE_Z + CHASSIS_Z - CarSpec.wheel_radius  # the tread, above base_link
    return forward - REAR_AXLE_X, up + CHASSIS_Z - ground, math.degrees(CAMERA_PITCH)


@dataclass(frozen=True)
class Lens:
    width: int  # [px]
    height: int  # [px]
    horizontal_fov: float  # [deg]

    @property
    def focal(self) -> float:
        """[px] for square pixels."""
        return (self.width / 2) / math.tan(math.radians(self.horizontal_fov) / 2)

    @property
    def matrix(self) -> np.ndarray:
        f = self.focal
        return np.array([[f, 0.0, self.width / 2], [0.0, f, self.height / 2], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class Mount:
    """Where a camera sits relative to a pose (x, y, yaw): ``forward`` along the heading,
    ``left`` across it, ``height`` above the ground, pitched down by ``pitch``."""

    forward: float  # [m]
    height: float  # [m]
    pitch: float  # [deg] down from horizontal
    left: float = 0.0  # [m]


@dataclass(frozen=True)
class Solid:
    """A box standing on the ground: an obstacle, a bot car, or the agent's car for spectators."""

    x: float  # [m] middle of the footprint
    y: float  # [m]
    yaw: float  # [rad]
    length: float  # [m]
    width: float  # [m]
    height: float  # [m]
    shade: int | tuple[int, int, int]  # gray level, or BGR colour


# Faces of a box by corner index (0-3 bottom, 4-7 top; counter-clockwise seen from outside).
_FACES = ((4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7))
_FACE_LIGHT = (1.0, 0.78, 0.62, 0.7, 0.86)  # top, then the four sides: a fixed light from above
_FACE_CORNERS = np.array(_FACES)


class PerspectiveView:
    """A camera's picture of the track and the solids on it."""

    def __init__(
        self,
        texture: TrackTexture,
        lens: Lens,
        mount: Mount,
        sky: int | tuple[int, int, int],
        room: Room | None = None,
    ) -> None:
        self.texture = texture
        self.lens = lens
        self.mount = mount
        self.room = room
        self._k = lens.matrix
        self._texture_from_world = texture.world_to_pixel
        pitch = math.radians(mount.pitch)
        self._sin_pitch, self._cos_pitch = math.sin(pitch), math.cos(pitch)
        horizon = lens.height / 2 - lens.focal * math.tan(pitch)
        self._sky_rows = int(np.clip(math.ceil(horizon) + 1, 0, lens.height))
        channels = () if isinstance(sky, int) else (3,)
        self._sky = np.empty((self._sky_rows, lens.width, *channels), dtype=np.uint8)
        self._sky[:] = sky
        self._border = sky if isinstance(sky, int) else tuple(int(c) for c in sky)
        # a world's field runs on to its edge beyond the part of it the track image holds: the
        # image's own edge, grass, repeated (recoloured with it in a randomised look); where the
        # image is the whole field, beyond it is nothing
        beyond = room is not None and room.field is not None
        self._border_mode = cv2.BORDER_REPLICATE if beyond else cv2.BORDER_CONSTANT
        if room is not None and room.height is not None:  # each column's ray at the horizon
            pixels = np.stack(
                [np.arange(lens.width), np.full(lens.width, horizon), np.ones(lens.width)]
            )
            self._column_rays = (np.linalg.inv(self._k) @ pixels).T
            self._rows = np.arange(lens.height)[:, None]
            self._levels = np.array([[room.height], [0.0]])  # the edge's top and foot [m]
            if room.field is None:
                height, width = texture.image.shape[:2]
                low = np.asarray(texture.origin, dtype=np.float64)
                self._field = (low, low + np.array([width, height]) / texture.pixels_per_metre)
            else:
                self._field = (np.array(room.field[:2]), np.array(room.field[2:]))

    def pose(self, x: float, y: float, yaw: float) -> tuple[np.ndarray, np.ndarray]:
        """The world-to-camera rotation (rows: right, down, forward) and the camera's position."""
        c, s = math.cos(yaw), math.sin(yaw)
        m = self.mount
        position = np.array(
            [x + m.forward * c - m.left * s, y + m.forward * s + m.left * c, m.height]
        )
        forward = np.array([c * self._cos_pitch, s * self._cos_pitch, -self._sin_pitch])
        right = np.array([s, -c, 0.0])
        down = np.cross(forward, right)
        return np.vstack([right, down, forward]), position

    def render(self, x: float, y: float, yaw: float, solids: list[Solid] = ()) -> np.ndarray:
        """The picture from the car at pose (x, y, yaw)."""
        rotation, position = self.pose(x, y, yaw)
        return self.render_from(rotation, position, solids)

    def render_from(
        self, rotation: np.ndarray, position: np.ndarray, solids: list[Solid] = ()
    ) -> np.ndarray:
        """The picture from a camera pose that ``pose`` gave: for a caller that draws more on
        it with the same pose."""
        t = -rotation @ position
        image_from_ground = self._k @ np.column_stack([rotation[:, 0], rotation[:, 1], t])
        texture_from_image = self._texture_from_world @ np.linalg.inv(image_from_ground)
        image = cv2.warpPerspective(
            self.texture.image,
            texture_from_image,
            (self.lens.width, self.lens.height),
            flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
            borderMode=self._border_mode,
            borderValue=self._border,
        )
        if self.room is None or self.room.height is None:
            image[: self._sky_rows] = self._sky
        else:
            top, foot = self._edge_rows(rotation, position)
            seen = min(self.lens.height, math.ceil(foot.max()))  # rows down to the lowest foot
            rows, block = self._rows[:seen], image[:seen]
            block[rows < foot] = self._border  # the edge, down to where it meets the ground
            block[rows < top] = self.room.background  # and over its top
        if solids:
            self.draw_solids(image, solids, rotation, position)
        return image

    def _edge_rows(
        self, rotation: np.ndarray, position: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where the field's edge shows in each column: the rows of its top and of its foot,
        where the column's ray at the horizon meets it (the camera does not roll, so the edge's
        top and foot each stay within a fraction of a pixel of one row per column). Below the
        horizon the foot hides the ground beyond the field; above, the top meets the
        background."""
        rays = self._column_rays
        directions = rays @ rotation  # in the world's axes
        low, high = self._field
        across = 1.0 / (directions[:, :2] + 1e-12)
        here = position[:2]
        reach = np.maximum((high - here) * across, (low - here) * across).min(axis=1)
        reach = np.maximum(reach, 0.01)  # a camera beyond the field: its edge at the lens
        # a point of the edge above where the ray meets it, in the camera's axes: reach times
        # the ray, raised along the world's up axis (rotation's third column) to the edge's top,
        # or lowered to the ground
        rise = self._levels - (position[2] + reach * directions[:, 2])  # (2, width)
        down = reach * rays[:, 1] + rise * rotation[1, 2]
        ahead = reach * rays[:, 2] + rise * rotation[2, 2]
        top, foot = self._k[1, 1] * down / ahead + self._k[1, 2]
        return top, foot

    def draw_solids(
        self, image: np.ndarray, solids: list[Solid], rotation: np.ndarray, position: np.ndarray
    ) -> None:
        forward = rotation[2]
        near = []
        for solid in solids:
            dx, dy = solid.x - position[0], solid.y - position[1]
            reach = math.hypot(dx, dy)
            # Out of sight: far enough to be under a pixel, or wholly behind the camera.
            if reach > DRAW_DISTANCE or (dx * forward[0] + dy * forward[1]) < -solid.length:
                continue
            near.append((reach, solid))
        for _, solid in sorted(near, key=lambda item: -item[0]):
            self._fill_faces(image, solid, rotation, position)

    def fill_polygons(
        self,
        image: np.ndarray,
        polygons: np.ndarray,
        shade: int | tuple[int, int, int],
        rotation: np.ndarray,
        position: np.ndarray,
    ) -> None:
        """Fill flat convex polygons given by their world corners (k x n x 3, metres) in the
        order given, clipped at the near plane; the caller decides which face the camera."""
        camera = (polygons - position) @ rotation.T
        if not (camera[..., 2] >= NEAR).all():
            camera = [_clip_near(polygon) for polygon in camera]
        for polygon in camera:
            if len(polygon) < 3:
                continue
            pixels = np.round(
                (polygon[:, :2] / polygon[:, 2:3] * self._k[0, 0] + self._k[:2, 2]) * 16
            ).astype(np.int32)
            cv2.fillConvexPoly(image, pixels, shade, cv2.LINE_AA, 4)

    def fill_solids(
        self, image: np.ndarray, solids: list[Solid], rotation: np.ndarray, position: np.ndarray
    ) -> None:
        """Draw solids in the order given, with no depth sorting: the parts of one object whose
        order the caller knows (a car's wheels, body and cabin). Their corners are projected
        together, which keeps a many-part object about as cheap as one box."""
        if not solids:
            return
        x, y, yaw, half_length, half_width, height = np.array(
            [(s.x, s.y, s.yaw, s.length / 2, s.width / 2, s.height) for s in solids]
        ).T
        c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
        local = _UNIT_BOX * np.stack([half_length, half_width, height], axis=1)[:, None, :]
        corners = np.stack(
            [
                local[..., 0] * c - local[..., 1] * s + x[:, None],
                local[..., 0] * s + local[..., 1] * c + y[:, None],
                local[..., 2],
            ],
            axis=-1,
        )
        camera = (corners - position) @ rotation.T
        if not (camera[..., 2] >= NEAR).all():
            for solid in solids:
                self._fill_faces(image, solid, rotation, position)
            return
        pixels = np.round(
            (camera[..., :2] / camera[..., 2:3] * self._k[0, 0] + self._k[:2, 2]) * 16
        ).astype(np.int32)
        faces_pixels = np.ascontiguousarray(pixels[:, _FACE_CORNERS])  # OpenCV wants it dense
        dx, dy = position[0] - x, position[1] - y
        along, across = dx * c[:, 0] + dy * s[:, 0], -dx * s[:, 0] + dy * c[:, 0]
        facing = np.stack(
            [
                position[2] > height,
                across < -half_width,
                along > half_length,
                across > half_width,
                along < -half_length,
            ],
            axis=1,
        ).tolist()
        for solid, faces, visible in zip(solids, faces_pixels, facing, strict=True):
            for face, light, seen in zip(faces, _FACE_LIGHT, visible, strict=True):
                if seen:
                    cv2.fillConvexPoly(image, face, _lit(solid.shade, light), cv2.LINE_AA, 4)

    def _fill_faces(
        self, image: np.ndarray, solid: Solid, rotation: np.ndarray, position: np.ndarray
    ) -> None:
        c, s = math.cos(solid.yaw), math.sin(solid.yaw)
        hl, hw = solid.length / 2, solid.width / 2
        # Which faces look at the camera: the top when the camera is above it, and each side
        # whose outward normal points toward the camera.
        along = (position[0] - solid.x) * c + (position[1] - solid.y) * s
        across = -(position[0] - solid.x) * s + (position[1] - solid.y) * c
        facing = (position[2] > solid.height, across < -hw, along > hl, across > hw, along < -hl)
        corners = (_UNIT_BOX * (hl, hw, solid.height)) @ np.array(
            [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
        ) + (solid.x, solid.y, 0.0)
        camera = (corners - position) @ rotation.T
        in_front = camera[:, 2] >= NEAR
        if in_front.all():
            pixels = np.round(
                (camera[:, :2] / camera[:, 2:3] * self._k[0, 0] + self._k[:2, 2]) * 16
            ).astype(np.int32)
        for face, light, visible in zip(_FACES, _FACE_LIGHT, facing, strict=True):
            if not visible:
                continue
            if in_front.all():
                polygon = pixels[list(face)]
            else:
                clipped = _clip_near(camera[list(face)])
                if len(clipped) < 3:
                    continue
                polygon = np.round(
                    (clipped[:, :2] / clipped[:, 2:3] * self._k[0, 0] + self._k[:2, 2]) * 16
                ).astype(np.int32)
            cv2.fillConvexPoly(image, polygon, _lit(solid.shade, light), cv2.LINE_AA, 4)


# A box's corners in its own frame, before scaling by (half length, half width, height).
_UNIT_BOX = np.array(
    [
        [-1, -1, 0],
        [1, -1, 0],
        [1, 1, 0],
        [-1, 1, 0],
        [-1, -1, 1],
        [1, -1, 1],
        [1, 1, 1],
        [-1, 1, 1],
    ],
    dtype=np.float64,
)


def _clip_near(polygon: np.ndarray) -> np.ndarray:
    """The part of a convex polygon (camera coordinates) in front of the near plane."""
    depth = polygon[:, 2]
    if (depth >= NEAR).all():
        return polygon
    kept = []
    for i in range(len(polygon)):
        a, b = polygon[i], polygon[(i + 1) % len(polygon)]
        if a[2] >= NEAR:
            kept.append(a)
        if (a[2] >= NEAR) != (b[2] >= NEAR):
            t = (NEAR - a[2]) / (b[2] - a[2])
            kept.append(a + t * (b - a))
    return np.array(kept)


@functools.lru_cache(maxsize=256)  # a handful of shades times five lights, asked every frame
def _lit(shade: int | tuple[int, int, int], light: float):
    if isinstance(shade, int):
        return int(shade * light)
    return tuple(int(c * light) for c in shade)
