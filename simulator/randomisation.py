"""Domain randomisation: every episode's scene drawn afresh from the episode's seed, as DeepRacer
for Cloud's DR_ENABLE_DOMAIN_RANDOMIZATION has simapp do, and more.

What simapp does (01f5f01): with ENABLE_DOMAIN_RANDOMIZATION (DRfC's defaults/template-run.env:9,
passed on by scripts/training/prepare-config.py:54 and scripts/evaluation/prepare-config.py:76;
read at bundle/markov/rollout_worker.py:774 and evaluation_worker.py:499) it randomises the
scene at the end of every reset (environments/deepracer_racetrack_env.py:222-223), so once per
episode. Every light of the world gets a diffuse colour with r, g and b each uniform in [0, 1]
and attenuation terms each uniform in [0, 1] (rollout_utils.py:92-118,
domain_randomizations/visual/light_randomizer.py:56-61,77-95); every box one colour, r, g and b
uniform in [0, 1] (agent_ctrl/obstacles_agent_ctrl.py:81-86, ModelRandomizerType.MODEL;
visual/model_visual_randomizer.py:71-73,104-111,131-136); every part of a bot car a colour of its
own (agent_ctrl/bot_cars_agent_ctrl.py:118-123, ModelRandomizerType.VISUAL). The track, the
ground, the camera and the car stay as they are there.

The car sees in gray, as DeepRacer's does (rl_coach observation_rgb_to_y_filter.py:45 weighs r,
g and b 0.2989, 0.5870 and 0.1140), so a light's colour reaches it as brightness, and an
object's colour as a gray level. What we add, each range our own and modest: the track's and
the ground's gray levels and a mottled texture over them, camera noise and blur, a jittered
camera mount, and jittered tyre grip and motor calibration. Off, nothing here runs: the
picture is the plain one, bit for bit.

A ``Scene`` holds the plain cameras and car; ``Scene.draw(rng)`` draws an episode's ``Look``
from the environment's ``np_random`` at reset and dresses the cameras in it (``LookView``, a
``PerspectiveView`` that recolours the track image once per episode and each frame's solids,
and adds blur and noise to each frame).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from simulator.camera import PerspectiveView, Solid
from simulator.car import CarSpec
from simulator.randomisation_ranges import (  # the ranges, apart for the web tier
    AMBIENT,
    BLUR,
    COLOUR_RANGE,
    FRICTION,
    INTENSITY,
    LIGHT_GAIN,
    LUMA,
    MOTOR,
    MOUNT_JITTER,
    NOISE,
    PART_SHIFT,
    SHADES,
    TEXTURE_SIZE,
    TEXTURE_STRENGTH,
)
from simulator.texture import TrackTexture

_NOISE_MARGIN = 32  # [px] each frame's noise is a window of a larger field, at random


def luma(colour: np.ndarray) -> np.ndarray:
    """The gray level (0-1) of r, g, b colours (..., 3) in [0, 1], as DeepRacer's camera sees."""
    return np.asarray(colour) @ np.array(LUMA)


@dataclass(frozen=True)
class Look:
    """How one episode's scene looks, and the car's small differences in it."""

    brightness: float  # [x] the light's, over the whole picture
    shifts: tuple[int, ...]  # [gray levels] one for each part level of the track image, in order
    sky_shift: int  # [gray levels]
    texture_strength: float  # [x]
    texture_size: float  # [m]
    shades: tuple[int, ...]  # the objects' gray levels, in the order they are drawn
    noise: float  # [gray levels]
    blur: float  # [px]
    mount: tuple[float, float, float, float]  # added to forward, height, pitch, left
    friction: float  # [x]
    motor: float  # [x]
    seed: int  # the texture's and the frames' noise

    @classmethod
    def draw(cls, rng: np.random.Generator, parts: int) -> Look:
        """A look drawn from ``rng`` for a track image of ``parts`` part levels."""
        uniform = rng.uniform
        light = luma(uniform(*COLOUR_RANGE, 3))
        colours = uniform(*COLOUR_RANGE, (SHADES, 3))
        return cls(
            brightness=float((AMBIENT + LIGHT_GAIN * light) * uniform(*INTENSITY)),
            shifts=tuple(int(s) for s in rng.integers(-PART_SHIFT, PART_SHIFT + 1, parts)),
            sky_shift=int(rng.integers(-PART_SHIFT, PART_SHIFT + 1)),
            texture_strength=float(uniform(*TEXTURE_STRENGTH)),
            texture_size=float(uniform(*TEXTURE_SIZE)),
            shades=tuple(round(255 * float(v)) for v in luma(colours)),
            noise=float(uniform(*NOISE)),
            blur=float(uniform(*BLUR)),
            mount=tuple(float(uniform(-limit, limit)) for limit in MOUNT_JITTER),
            friction=float(uniform(*FRICTION)),
            motor=float(uniform(*MOTOR)),
            seed=int(rng.integers(2**63)),
        )


def part_levels(image: np.ndarray, *, most: int = 6, share: float = 0.002) -> list[int]:
    """The gray levels a track image's parts are drawn in: its most common levels (each at least
    ``share`` of the pixels, 6 levels apart), read from the image rather than assumed, so that a
    change of the track's colours changes what is randomised with it."""
    counts = np.bincount(image.ravel(), minlength=256)
    levels: list[int] = []
    for level in np.argsort(counts, kind="stable")[::-1]:
        if counts[level] < share * image.size or len(levels) == most:
            break
        if all(abs(int(level) - kept) >= 6 for kept in levels):
            levels.append(int(level))
    return sorted(levels)


def _scaled(level, brightness: float):
    """A gray level, or each channel of a colour, times ``brightness``, kept within 0-255."""
    if isinstance(level, tuple):
        return tuple(_scaled(channel, brightness) for channel in level)
    return min(255, max(0, round(level * brightness)))


def recoloured(texture: TrackTexture, levels: list[int], look: Look) -> TrackTexture:
    """``texture`` in ``look``'s light and colours: each part level moved by its shift, the
    levels between them moved in proportion (the edges' antialiasing stays smooth), all scaled
    by the brightness, and a mottled texture laid over the whole."""
    knots = [0, *levels, 255]
    targets = [0, *(level + shift for level, shift in zip(levels, look.shifts, strict=False)), 255]
    if knots[1] == 0:
        knots, targets = knots[1:], targets[1:]
    if knots[-2] == 255:
        knots, targets = knots[:-1], targets[:-1]
    table = (
        np.clip(
            np.interp(np.arange(256), knots, np.clip(targets, 0, 255)) * look.brightness, 0, 255
        )
        .round()
        .astype(np.uint8)
    )
    image = cv2.LUT(texture.image, table)
    if look.texture_strength > 0:
        height, width = image.shape[:2]
        cell = max(2, round(look.texture_size * texture.pixels_per_metre))
        rng = np.random.default_rng(look.seed)
        # The gain in 128ths, in uint8 as the image is: OpenCV multiplies those many times faster
        # than floats (a reset's cost, where a young model's episodes last a few steps).
        coarse = 128 + 127 * look.texture_strength * rng.uniform(
            -1.0, 1.0, (height // cell + 2, width // cell + 2)
        )
        gain = cv2.resize(
            coarse.round().astype(np.uint8), (width, height), interpolation=cv2.INTER_CUBIC
        )
        if image.ndim == 3:
            gain = cv2.merge([gain] * image.shape[2])
        image = cv2.multiply(image, gain, scale=1 / 128)
    return dataclasses.replace(texture, image=image)


@functools.lru_cache(maxsize=4)
def _unit_noise(height: int, width: int) -> np.ndarray:
    """A field of standard normal noise, the same in every process, that each frame's noise is
    a window of (drawn once: a fresh field each episode would cost a reset more than the
    rest of its look)."""
    return np.random.default_rng(0).standard_normal((height, width), dtype=np.float32)


class LookView(PerspectiveView):
    """A camera dressed in an episode's look: its recoloured track image and sky (given), the
    objects in the look's shades, and each frame blurred and noisy as the look says."""

    def __init__(
        self,
        plain: PerspectiveView,
        texture: TrackTexture,
        sky,
        look: Look,
        rng: np.random.Generator,
    ) -> None:
        forward, height, pitch, left = look.mount
        m = plain.mount
        mount = dataclasses.replace(
            m,
            forward=m.forward + forward,
            height=m.height + height,
            pitch=m.pitch + pitch,
            left=m.left + left,
        )
        room = plain.room and dataclasses.replace(
            plain.room, background=_scaled(plain.room.background, look.brightness)
        )
        super().__init__(texture, plain.lens, mount, sky, room)
        self.look = look
        self._rng = rng  # shared by a stereo pair's two views, drawn in the order they render
        self._shades = [_scaled(shade, look.brightness) for shade in look.shades]
        side = 2 * math.ceil(2 * look.blur) + 1
        self._blur = (side, side) if look.blur >= 0.1 else None
        self._noise = None
        if look.noise > 0:
            unit = _unit_noise(plain.lens.height + _NOISE_MARGIN, plain.lens.width + _NOISE_MARGIN)
            self._noise = (unit * look.noise).round().astype(np.int16)

    def shade(self, index: int) -> int:
        """The gray level of the ``index``-th object drawn, in the look's light."""
        return self._shades[index % len(self._shades)]

    def dressed(self, solids: list[Solid]) -> list[Solid]:
        """``solids`` in the look's colours, one each in the order they come (the traffic's)."""
        return [dataclasses.replace(solid, shade=self.shade(i)) for i, solid in enumerate(solids)]

    def render_from(
        self, rotation: np.ndarray, position: np.ndarray, solids: list[Solid] = ()
    ) -> np.ndarray:
        image = super().render_from(rotation, position, self.dressed(solids))
        if self._blur:  # a kernel of 2 sigma each side: OpenCV's own choice, 3, costs twice
            image = cv2.GaussianBlur(image, self._blur, self.look.blur)
        if self._noise is not None:
            row, column = self._rng.integers(0, _NOISE_MARGIN + 1, 2)
            height, width = image.shape[:2]
            window = self._noise[row : row + height, column : column + width]
            if image.ndim == 3:
                window = cv2.merge([window] * image.shape[2])
            image = cv2.add(image, window, dtype=cv2.CV_8U)  # saturates at 0 and 255
        return image


class Scene:
    """The plain cameras and car of an environment, and the looks an episode may be given."""

    def __init__(
        self, cameras: list[PerspectiveView], car: CarSpec, sky: int | tuple[int, int, int]
    ) -> None:
        self.cameras = list(cameras)
        self.car = car
        self.sky = sky
        self.levels = part_levels(cameras[0].texture.image)

    def draw(self, rng: np.random.Generator) -> tuple[list[PerspectiveView], CarSpec, Look]:
        """An episode's look drawn from ``rng`` (the environment's ``np_random`` at reset): the
        cameras dressed in it, the car with its jitter, and the look."""
        look = Look.draw(rng, len(self.levels))
        texture = recoloured(self.cameras[0].texture, self.levels, look)
        shifted = (
            tuple(c + look.sky_shift for c in self.sky)
            if isinstance(self.sky, tuple)
            else self.sky + look.sky_shift
        )
        sky = _scaled(shifted, look.brightness)
        frames = np.random.default_rng(look.seed ^ 0x5EED)  # each frame's noise window
        cameras = [LookView(camera, texture, sky, look, frames) for camera in self.cameras]
        car = dataclasses.replace(
            self.car,
            friction=self.car.friction * look.friction,
            command_radius=self.car.command_radius / look.motor,
        )
        return cameras, car, look
