"""The spectator's picture: the racer's car drawn as a car, not as one more box."""

import math

import numpy as np

from simulator.camera import Solid
from simulator.spectator import DRAWN_HEIGHT, WHEEL, status_line, view_image
from tests.simulator.conftest import drive

RED = (47, 36, 209)  # BGR of the garage's red shell
BLUE = (218, 105, 9)


def _pixel(spectator, car, forward: float, left: float, up: float) -> tuple[int, int]:
    """Where a point given in the car's frame (metres from the middle of its rear axle) appears
    in the chase view."""
    rotation, position = spectator.chase.pose(car.x, car.y, car.yaw)
    c, s = math.cos(car.yaw), math.sin(car.yaw)
    world = np.array([car.x + forward * c - left * s, car.y + forward * s + left * c, up])
    u, v, w = spectator.chase.lens.matrix @ (rotation @ (world - position))
    return round(v / w), round(u / w)


def _as_one_box(env) -> np.ndarray:
    """The same scene with the car drawn as the box it used to be."""
    car, spec, spectator = env.car, env.car.spec, env.spectator
    x, y = car.point_ahead(spec.centre_offset)
    box = Solid(x, y, car.yaw, spec.length, spec.width, DRAWN_HEIGHT, env.car_colour)
    return spectator.chase.render(car.x, car.y, car.yaw, [box])


def test_the_racers_car_has_dark_wheels_at_its_corners_and_a_shell_coloured_body(environments):
    env = environments(track="rookie-loop", car_colour=RED)
    env.reset(seed=1)
    drive(env, steps=5)
    car, spectator = env.unwrapped.car, env.unwrapped.spectator
    frame = view_image(env.unwrapped, "spectator")
    box = _as_one_box(env.unwrapped)
    spec = car.spec
    outside = spec.wheel_track / 2 + WHEEL[1] / 2 - 0.004  # the outer edge of a rear wheel
    for side in (1, -1):
        row, column = _pixel(spectator, car, -WHEEL[0] / 2 - 0.001, side * outside, WHEEL[0] / 2)
        wheel = frame[row - 1 : row + 2, column - 1 : column + 2].reshape(-1, 3)
        assert wheel.max() < 60, f"the {side} rear wheel is not dark: {wheel.tolist()}"
        boxed = box[row - 1 : row + 2, column - 1 : column + 2].reshape(-1, 3)
        assert (np.abs(boxed.astype(int) - RED).sum(axis=1) < 120).all(), "a box is red there"
    blue, green, red = frame[
        _pixel(spectator, car, spec.centre_offset + 0.12, 0.0, DRAWN_HEIGHT / 2)
    ]
    assert red > 150 and green < 60 and blue < 70  # the bonnet, in the shell colour


def test_the_racers_car_shows_its_rear_window_to_the_chase_camera(environments):
    env = environments(track="rookie-loop", car_colour=RED)
    env.reset(seed=1)
    car, spectator = env.unwrapped.car, env.unwrapped.spectator
    frame = view_image(env.unwrapped, "spectator")
    spec = car.spec
    rear_of_cabin = spec.centre_offset - 0.02 - 0.45 * spec.length / 2
    blue, green, red = frame[_pixel(spectator, car, rear_of_cabin, 0.0, 0.75 * DRAWN_HEIGHT)]
    assert blue > red and max(blue, green, red) < 110  # tinted glass, not the red shell


def test_the_map_shows_the_car_nose_first(environments):
    env = environments(track="rookie-loop", car_colour=RED)
    env.reset(seed=1)
    car, spectator = env.unwrapped.car, env.unwrapped.spectator
    frame = view_image(env.unwrapped, "spectator")
    x, y = car.point_ahead(car.spec.centre_offset)
    left, top = spectator._map_at
    texture = spectator._map_texture
    centre, ahead = texture.to_pixels(np.array([(x, y), car.point_ahead(1.0)]))
    forward = (ahead - centre) / np.linalg.norm(ahead - centre)

    def colour_at(along: float) -> np.ndarray:
        column, row = np.round(centre + along * forward).astype(int)
        return frame[top + row, left + column].astype(int)

    def is_red(pixel: np.ndarray) -> bool:
        return pixel[2] > 150 and pixel[1] < 90 and pixel[0] < 90

    assert is_red(colour_at(5.0)), "the nose points the way the car faces"
    assert not is_red(colour_at(-8.0)), "the car's tail ends before it"


def test_a_box_between_the_camera_and_the_car_hides_the_car(environments):
    env = environments(track="rookie-loop", car_colour=RED)
    env.reset(seed=1)
    unwrapped = env.unwrapped
    car, spectator = unwrapped.car, unwrapped.spectator
    x, y = car.point_ahead(-0.45)  # between the car and the chase camera 0.9 m behind it

    class Nearby:
        actors = []

        @staticmethod
        def solids(colour: bool = False) -> list[Solid]:
            return [Solid(x, y, car.yaw, 0.1, 0.4, 0.4, (64, 160, 232))]

    unwrapped.traffic, traffic = Nearby(), unwrapped.traffic
    try:
        frame = view_image(unwrapped, "spectator")
    finally:
        unwrapped.traffic = traffic
    _blue, green, red = frame[_pixel(spectator, car, car.spec.centre_offset, 0.0, 0.06)]
    assert red > 150 and green > 100  # the orange box, not the red car


def test_what_the_policy_sees_does_not_show_the_racers_own_car(environments):
    observations = []
    for colour in (RED, BLUE):
        env = environments(track="rookie-loop", car_colour=colour, race_type="OBJECT_AVOIDANCE")
        observation, _ = env.reset(seed=4)
        view_image(env.unwrapped, "spectator")  # the spectator draws on its own picture only
        observations.append(observation)
    first, second = observations
    assert first.keys() == second.keys()
    for key in first:
        assert np.array_equal(first[key], second[key])


def test_it_numbers_no_training_episode_of_its_own_only_an_evaluations_lap(environments):
    training = environments(track="rookie-loop")
    for seed in (1, 2):  # a car's second episode: its own count, not the job's, would say 1
        training.reset(seed=seed)
    drive(training, steps=3)
    line = status_line(training.unwrapped)
    assert "Episode" not in line
    assert line.endswith(" s") and "m/s" in line and "%" in line

    evaluation = environments(track="rookie-loop", mode="evaluation")
    evaluation.reset(seed=1)
    assert status_line(evaluation.unwrapped).startswith("Lap 1/")
