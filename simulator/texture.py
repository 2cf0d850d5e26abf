"""Top-down images of a track: what the camera projects, what spectators see, and track previews.

The track is flat, so one image of it, drawn once, stands in for the ground: cameras project it
through a homography instead of rendering 3D geometry. It looks like a DeepRacer track: a dark
surface, white borders, a dashed centre line and a start line, on light surroundings.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simulator.tracks import Track

BORDER_WIDTH = 0.05  # [m] DeepRacer's border tape is about 2 inches
CENTRE_LINE_WIDTH = 0.03  # [m]
DASH = 0.15  # [m] dash and gap of the centre line
MARGIN = 1.0  # [m] of surroundings around the track

# (grayscale, BGR colour) for each part of the picture
SURROUNDINGS = (196, (200, 212, 216))
SURFACE = (58, (62, 60, 58))
BORDER = (250, (250, 250, 250))
CENTRE_LINE = (214, (40, 200, 240))
START_LINE = (250, (250, 250, 250))


@dataclass(frozen=True)
class TrackTexture:
    """An image of the track with the affine map from world metres to its pixels."""

    image: np.ndarray  # (H, W) uint8, or (H, W, 3) BGR
    pixels_per_metre: float
    origin: np.ndarray  # world (x, y) at the image's bottom-left corner

    @property
    def world_to_pixel(self) -> np.ndarray:
        """3x3 matrix taking homogeneous world (x, y, 1) to pixel (column, row, 1); y points up."""
        s, height = self.pixels_per_metre, self.image.shape[0]
        return np.array(
            [[s, 0.0, -s * self.origin[0]], [0.0, -s, height + s * self.origin[1]], [0, 0, 1]]
        )

    def to_pixels(self, points: np.ndarray) -> np.ndarray:
        """World (k, 2) points as float pixel coordinates."""
        points = np.asarray(points, dtype=np.float64)
        s, height = self.pixels_per_metre, self.image.shape[0]
        return np.column_stack(
            [(points[:, 0] - self.origin[0]) * s, height - (points[:, 1] - self.origin[1]) * s]
        )


def render(track: Track, *, pixels_per_metre: float, colour: bool = False) -> TrackTexture:
    """Draw ``track`` at ``pixels_per_metre``, in grayscale (the camera's) or BGR colour."""
    low, high = track.bounds
    origin = low - MARGIN
    size = np.ceil((high - low + 2 * MARGIN) * pixels_per_metre).astype(int)
    pick = 1 if colour else 0
    shape = (size[1], size[0], 3) if colour else (size[1], size[0])
    image = np.empty(shape, dtype=np.uint8)
    image[:] = SURROUNDINGS[pick]
    texture = TrackTexture(image=image, pixels_per_metre=pixels_per_metre, origin=origin)

    shift = 4  # sub-pixel precision for OpenCV's drawing functions
    scale = float(1 << shift)

    def fixed(points: np.ndarray) -> np.ndarray:
        return np.round(texture.to_pixels(points) * scale).astype(np.int32)

    inner, outer = fixed(track.inner), fixed(track.outer)
    for i in range(len(inner) - 1):  # the surface, one quad per segment, whichever way it winds
        quad = np.array([inner[i], inner[i + 1], outer[i + 1], outer[i]])
        cv2.fillConvexPoly(image, quad, SURFACE[pick], cv2.LINE_AA, shift)

    def line(points: np.ndarray, width: float, value) -> None:
        thickness = max(1, round(width * pixels_per_metre))
        cv2.polylines(image, [fixed(points)], False, value, thickness, cv2.LINE_AA, shift)

    # The dashed centre line: alternate stretches of DASH metres.
    distances = np.arange(0.0, track.length, DASH / 4)
    xs, ys, _ = track.point_at(distances)
    on = (distances // DASH).astype(int) % 2 == 0
    starts = np.flatnonzero(on & ~np.roll(on, 1))
    for start in starts:
        stop = start
        while stop + 1 < len(on) and on[stop + 1]:
            stop += 1
        line(np.column_stack([xs[start : stop + 1], ys[start : stop + 1]]), CENTRE_LINE_WIDTH,
             CENTRE_LINE[pick])  # fmt: skip

    line(track.inner, BORDER_WIDTH, BORDER[pick])
    line(track.outer, BORDER_WIDTH, BORDER[pick])
    line(np.array([track.inner[0], track.outer[0]]), BORDER_WIDTH, START_LINE[pick])
    return texture


def preview(track: Track, *, width: int = 480) -> np.ndarray:
    """A colour top-down picture of the track, ``width`` pixels wide, with an arrow at the start
    showing the direction of travel."""
    return preview_texture(track, width=width).image


def preview_png(track: Track, *, width: int = 480) -> bytes:
    """``preview`` as a PNG file's bytes."""
    encoded, png = cv2.imencode(
        ".png", preview(track, width=width), [cv2.IMWRITE_PNG_COMPRESSION, 9]
    )
    if not encoded:
        raise ValueError("the track's preview could not be encoded")
    return png.tobytes()


def preview_texture(track: Track, *, width: int = 480) -> TrackTexture:
    """``preview``'s picture with its world-to-pixel transform, for drawing on it."""
    low, high = track.bounds
    texture = render(track, pixels_per_metre=width / float(high[0] - low[0] + 2 * MARGIN),
                     colour=True)  # fmt: skip
    image = texture.image[:, :width].copy()  # ceil() may have added a column
    x, y, heading = track.point_at(0.0)
    start = texture.to_pixels(np.array([[x, y]]))[0]
    tip = texture.to_pixels(np.array([[x + 0.9 * np.cos(heading), y + 0.9 * np.sin(heading)]]))[0]
    cv2.arrowedLine(image, tuple(np.round(start).astype(int)), tuple(np.round(tip).astype(int)),
                    (30, 110, 235), 3, cv2.LINE_AA, tipLength=0.35)  # fmt: skip
    return TrackTexture(image=image, pixels_per_metre=texture.pixels_per_metre,
                        origin=texture.origin)  # fmt: skip
