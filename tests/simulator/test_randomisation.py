"""Domain randomisation: each episode of a randomised run draws its scene from the episode's seed,
so scenes differ per episode and repeat with their seed; off, the picture is the plain one."""

from __future__ import annotations

import numpy as np

from simulator import randomisation
from simulator.camera import PerspectiveView
from simulator.env import DeepRacerEnv
from simulator.randomisation import Look, LookView, part_levels, recoloured
from simulator.texture import render

CAMERA = "FRONT_FACING_CAMERA"


def frame(env: DeepRacerEnv, seed: int | None = None) -> np.ndarray:
    observation, _ = env.reset(seed=seed)
    return observation[CAMERA][0]


def test_a_randomised_scene_differs_per_episode_and_repeats_with_its_seed():
    env = DeepRacerEnv(track="rookie-loop", mode="evaluation", randomise=True)
    first, first_look = frame(env, seed=7), env.look
    second, second_look = frame(env), env.look
    again = frame(env, seed=7)

    assert not np.array_equal(first, second)
    assert first_look != second_look
    assert np.array_equal(first, again)
    assert env.look == first_look
    # and in another environment, as a worker elsewhere would draw it
    elsewhere = DeepRacerEnv(track="rookie-loop", mode="evaluation", randomise=True)
    assert np.array_equal(frame(elsewhere, seed=7), first)


def test_a_randomised_episodes_frames_repeat_with_its_seed_noise_and_all():
    env = DeepRacerEnv(track="rookie-loop", randomise=True)

    def drive() -> list[np.ndarray]:
        frames = [frame(env, seed=3)]
        for _ in range(5):
            observation, *_ = env.step(0)
            frames.append(observation[CAMERA][0])
        return frames

    one, two = drive(), drive()
    assert all(np.array_equal(a, b) for a, b in zip(one, two, strict=True))
    # the noise is drawn anew each frame: the car at rest sees two different pictures
    still = DeepRacerEnv(track="rookie-loop", randomise=True)
    frame(still, seed=3)
    assert still.look.noise > 1  # seed 3's look has noise to see
    camera, car = still._cameras[0], still.car
    assert not np.array_equal(
        camera.render(car.x, car.y, car.yaw), camera.render(car.x, car.y, car.yaw)
    )


def test_off_the_frames_are_the_plain_cameras_frames():
    env = DeepRacerEnv(track="rookie-loop", mode="evaluation")
    camera = env._cameras[0]
    # a camera built here from the track's image, without the randomisation module
    plain = PerspectiveView(
        render(env.track, pixels_per_metre=env.config["camera_texture_ppm"]),
        camera.lens,
        camera.mount,
        camera.room.sky,
        camera.room,
    )
    for seed in (1, 2, None):
        seen = frame(env, seed)
        car = env.car
        assert type(env._cameras[0]) is PerspectiveView
        assert np.array_equal(seen, plain.render(car.x, car.y, car.yaw))
    assert not hasattr(env, "look")


def test_a_look_moves_the_track_images_own_levels_and_keeps_the_surface_darker():
    env = DeepRacerEnv(track="rookie-loop")
    texture = env._cameras[0].texture
    levels = part_levels(texture.image)
    rng = np.random.default_rng(0)
    assert len(levels) >= 3  # surface, ground and borders at least
    surface, borders = levels[0], levels[-1]
    for _ in range(20):
        look = Look.draw(rng, len(levels))
        image = recoloured(texture, levels, look).image
        where_surface, where_borders = texture.image == surface, texture.image == borders
        assert np.median(image[where_surface]) < np.median(image[where_borders])
        low, high = randomisation.INTENSITY
        assert randomisation.AMBIENT * low <= look.brightness
        assert look.brightness <= (randomisation.AMBIENT + randomisation.LIGHT_GAIN) * high
        assert all(abs(shift) <= randomisation.PART_SHIFT for shift in look.shifts)


def test_part_levels_are_an_images_most_common_gray_levels():
    image = np.full((100, 100), 196, dtype=np.uint8)
    image[20:80] = 58
    image[48:52] = 250
    image[0, 0] = 100  # one antialiased pixel is not a part
    assert part_levels(image) == [58, 196, 250]


def test_a_randomised_car_has_its_grip_and_motor_jittered_within_range():
    env = DeepRacerEnv(track="rookie-loop", randomise=True)
    plain = DeepRacerEnv(track="rookie-loop").car.spec
    grips, motors = set(), set()
    for seed in range(5):
        env.reset(seed=seed)
        spec = env.car.spec
        low, high = randomisation.FRICTION
        assert plain.friction * low <= spec.friction <= plain.friction * high
        # The motor's calibration: the same command turns the wheels up to MOTOR times as fast.
        motor = plain.command_radius / spec.command_radius
        assert randomisation.MOTOR[0] <= motor <= randomisation.MOTOR[1]
        assert abs(motor - env.look.motor) < 1e-9
        assert env.car.hinge.spec is spec  # the episode's car drives with it
        grips.add(spec.friction)
        motors.add(motor)
    assert len(grips) == len(motors) == 5


def test_boxes_take_the_looks_colours():
    env = DeepRacerEnv(track="rookie-loop", race_type="OBJECT_AVOIDANCE", randomise=True)
    env.reset(seed=0)
    camera = env._cameras[0]
    assert isinstance(camera, LookView)
    solids = env.traffic.solids()
    shades = [solid.shade for solid in camera.dressed(solids)]
    assert shades == [camera.shade(i) for i in range(len(solids))]
    assert shades != [solid.shade for solid in solids]


def test_a_stereo_pair_sees_one_look():
    env = DeepRacerEnv(track="rookie-loop", sensors=["STEREO_CAMERAS"], randomise=True)
    env.reset(seed=4)
    left, right = env._cameras
    assert left.look is right.look and left.texture is right.texture
    assert left.mount.left != right.mount.left
