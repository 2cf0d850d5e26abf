"""Top-down images of a track: what the camera projects, what spectators see, and track previews.

The track is flat, so one image of it, drawn once, stands in for the ground: cameras project it
through a homography instead of rendering 3D geometry. It is drawn as simapp draws its tracks:
a dark road whose white borders lie inside its edges, a dashed orange centre line and a
chequered start line, on grass, with the field's walls round it.

Every number is simapp's (at 01f5f01), from the meshes and textures nearly all its tracks share
(bundle/meshes/<track>/textures: 120 tracks use the same road, line and centre-line images, 117
the same grass, 102 the same wall). The widths are the meshes' own (reInvent2019_track.dae and
2022_reinvent_champ_ccw.dae alike): each border a 0.0762 m (3 in) band from the road's edge
inward (ol-verts and il-verts pair the road's outer vertices with ones 0.0762 m in), the centre
line dashes 0.0254 m wide and 0.0508 m long every 0.1016 m (cl-verts: 228 quads round the 23.1 m
re:Invent 2019, 328 round the 2022 championship), the start line a strip 0.066 m wide of two
rows of squares (2022_reinvent_champ_ccw.dae's Plane-mesh, textures/startline.png).

The colours are each texture's mean, as lit: in the frames of simapp's camera that
deepracer-utils publishes (tests/deepracer/model/sample-model/pictures/dr-demo-{1,2,3}.png, MIT),
frames of re:Invent 2018 (reinvent_base, whose bundle/meshes/reinvent/textures are its own), each
part of the ground reads 1.09-1.12 times its texture's luma (the road 51 for 46.6, the grass 135
for 119.9, the borders 212 for 193.4, the centre line 138 for 126.5) and the walls 14-24 for
wall.png's 61. The camera's gray is rl_coach's luma of the colour, as the agent's to_grayscale
filter takes it (bundle/rl_coach/rl_coach/filters/observation/observation_rgb_to_y_filter.py:45).
Other worlds light their tracks much alike (a sun and a few lamps); that they give the same 1.10
is assumed.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simulator.tracks import Track

BORDER_WIDTH = 0.0762  # [m] each border, inside the track's edge
CENTRE_LINE_WIDTH = 0.0254  # [m]
DASH = 0.0508  # [m] dash and gap of the centre line
START_LINE_WIDTH = 0.066  # [m] along the track
MARGIN = 1.0  # [m] of grass round Pitlane's own tracks, and round every track's preview
FIELD_DRAWN = 3.0  # [m] of a world's field drawn beyond the track: plain grass further out
GROUND_LIGHT = 1.10  # Gazebo's shading of the flat ground
WALL_LIGHT = 0.33  # and of the walls


def lit(rgb: tuple[float, float, float], light: float) -> tuple[int, tuple[int, int, int]]:
    """A texture's mean colour under ``light``: (the camera's gray level, BGR colour)."""
    red, green, blue = (min(255.0, channel * light) for channel in rgb)
    gray = round(0.2989 * red + 0.5870 * green + 0.1140 * blue)
    return gray, (round(blue), round(green), round(red))


# (grayscale, BGR colour) for each part of the picture, from each texture's mean RGB
SURROUNDINGS = lit((126.3, 133.2, 64.7), GROUND_LIGHT)  # field.png: grass
SURFACE = lit((63.6, 62.9, 61.3), GROUND_LIGHT)  # road.png
BORDER = lit((222.7, 222.6, 222.4), GROUND_LIGHT)  # outerLine.png (both borders)
CENTRE_LINE = lit((224.9, 143.4, 0.0), GROUND_LIGHT)  # centerLine.png: orange
START_LINE = lit((141.5, 141.5, 141.5), GROUND_LIGHT)  # startline.png: its squares' mean
WALL = lit((36.0, 70.0, 81.0), WALL_LIGHT)  # wall.png: what the camera sees above the grass
# and over the walls the world's background, unlit: SDF's default 0.7 gray (simulator.camera.Room)
BACKGROUND = (178, (178, 178, 178))
WALL_HEIGHT = 1.0  # [m] reinvent_base_wall_field_only.dae's wallShape


@dataclass(frozen=True)
class Style:
    """How a track is drawn: each part's (gray, BGR) and the lines' widths [m]."""

    surroundings: tuple = SURROUNDINGS
    surface: tuple = SURFACE
    border: tuple = BORDER
    centre_line: tuple = CENTRE_LINE
    start_line: tuple = START_LINE
    border_width: float = BORDER_WIDTH
    centre_line_width: float = CENTRE_LINE_WIDTH
    dash: float = DASH
    start_line_width: float = START_LINE_WIDTH
    borders_inside: bool = True  # each border a band inside the edge, else a line centred on it


SIMAPP = Style()
# re:Invent 2018 (reinvent_base): bundle/meshes/reinvent/textures' Road_DIFF, Grass_DIFF,
# SolidLine_DIFF and DashedLine_DIFF (as road.png, field.png, outerLine.png, centerLine.png), on
# the same widths (reinvent_base.dae: il/cl quads of 0.0762 and 0.0254 x 0.0508 m)
REINVENT_2018 = Style(
    surroundings=lit((95.2, 135.6, 104.3), GROUND_LIGHT),
    surface=lit((36.1, 48.5, 64.0), GROUND_LIGHT),
    border=lit((194.4, 193.6, 189.8), GROUND_LIGHT),
    centre_line=lit((194.4, 116.5, 0.0), GROUND_LIGHT),
    start_line=lit((36.1, 48.5, 64.0), GROUND_LIGHT),  # none: the road
)
# by WORLD_NAME; the others draw SIMAPP's textures (each world's field: simulator.camera.Room)
STYLES = {"reinvent_base": REINVENT_2018}


def style_for(track: Track) -> Style:
    """How simapp draws ``track``: its own textures where they differ from the common ones."""
    return STYLES.get(track.name, SIMAPP)


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


def _extent(track: Track, field: tuple[float, float, float, float] | None):
    """The corners of the ground a track image holds: MARGIN round the track, or its world's
    field as far as FIELD_DRAWN beyond it (a camera in a room sees the grass run on past the
    image's edge to the field's)."""
    low, high = track.bounds
    if field is None:
        return low - MARGIN, high + MARGIN
    low = np.maximum(np.minimum(field[:2], low), low - FIELD_DRAWN)
    return low, np.minimum(np.maximum(field[2:], high), high + FIELD_DRAWN)


def render(
    track: Track,
    *,
    pixels_per_metre: float,
    colour: bool = False,
    style: Style = SIMAPP,
    field: tuple[float, float, float, float] | None = None,
) -> TrackTexture:
    """Draw ``track`` at ``pixels_per_metre``, in grayscale (the camera's) or BGR colour, on
    ``field`` (x0, y0, x1, y1 [m]: its world's, as far as FIELD_DRAWN beyond the track) or
    MARGIN of grass round it."""
    origin, high = _extent(track, field)
    size = np.ceil((high - origin) * pixels_per_metre).astype(int)
    pick = 1 if colour else 0
    shape = (size[1], size[0], 3) if colour else (size[1], size[0])
    image = np.empty(shape, dtype=np.uint8)
    image[:] = style.surroundings[pick]
    texture = TrackTexture(image=image, pixels_per_metre=pixels_per_metre, origin=origin)

    shift = 4  # sub-pixel precision for OpenCV's drawing functions
    scale = float(1 << shift)

    def fixed(points: np.ndarray) -> np.ndarray:
        return np.round(texture.to_pixels(points) * scale).astype(np.int32)

    inner, outer = fixed(track.inner), fixed(track.outer)
    for i in range(len(inner) - 1):  # the surface, one quad per segment, whichever way it winds
        quad = np.array([inner[i], inner[i + 1], outer[i + 1], outer[i]])
        cv2.fillConvexPoly(image, quad, style.surface[pick], cv2.LINE_AA, shift)

    def line(points: np.ndarray, width: float, value) -> None:
        thickness = max(1, round(width * pixels_per_metre))
        cv2.polylines(image, [fixed(points)], False, value, thickness, cv2.LINE_AA, shift)

    def band(edge: np.ndarray, inside: np.ndarray, value) -> None:
        for i in range(len(edge) - 1):
            quad = np.array([edge[i], edge[i + 1], inside[i + 1], inside[i]])
            cv2.fillConvexPoly(image, quad, value, cv2.LINE_AA, shift)

    # The dashed centre line: quads centre_line_width across and dash long, a dash apart.
    half = style.centre_line_width / 2
    for start in np.arange(0.0, track.length - style.dash / 2, 2 * style.dash):
        along = np.linspace(start, start + style.dash, 5)
        left = np.column_stack(track.point_at(along, half)[:2])
        right = np.column_stack(track.point_at(along[::-1], -half)[:2])
        cv2.fillPoly(
            image, [fixed(np.vstack([left, right]))], style.centre_line[pick], cv2.LINE_AA, shift
        )

    if style.borders_inside:  # bands from each edge border_width toward the other edge
        across = track.outer - track.inner
        inward = across / np.linalg.norm(across, axis=1, keepdims=True) * style.border_width
        band(inner, fixed(track.inner + inward), style.border[pick])
        band(outer, fixed(track.outer - inward), style.border[pick])
    else:
        line(track.inner, style.border_width, style.border[pick])
        line(track.outer, style.border_width, style.border[pick])
    start = np.array([track.inner[0], track.outer[0]])
    line(start, style.start_line_width, style.start_line[pick])
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
    texture = render(
        track, pixels_per_metre=width / float(high[0] - low[0] + 2 * MARGIN), colour=True
    )
    image = texture.image[:, :width].copy()  # ceil() may have added a column
    x, y, heading = track.point_at(0.0)
    start = texture.to_pixels(np.array([[x, y]]))[0]
    tip = texture.to_pixels(np.array([[x + 0.9 * np.cos(heading), y + 0.9 * np.sin(heading)]]))[0]
    cv2.arrowedLine(
        image,
        tuple(np.round(start).astype(int)),
        tuple(np.round(tip).astype(int)),
        (30, 110, 235),
        3,
        cv2.LINE_AA,
        tipLength=0.35,
    )
    return TrackTexture(
        image=image, pixels_per_metre=texture.pixels_per_metre, origin=texture.origin
    )
