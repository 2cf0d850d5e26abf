"""The car's camera is DeepRacer's simulated camera: its lens, where it sits, and what follows
from them, checked by rendering. simapp's numbers are at 01f5f01 (the same at 2fc2d75c)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simulator.camera import (
    CAR_FOV,
    SIMAPP_FOV,
    STEREO_BASELINE,
    Lens,
    Mount,
    PerspectiveView,
    deepracer_mount,
)
from simulator.car import CarSpec, lidar_mount
from simulator.config import ConfigError
from simulator.env import DeepRacerEnv, default_config
from simulator.room import Room
from simulator.texture import TrackTexture

SKY, NEAR_GROUND, FAR_GROUND = 250, 40, 200


def test_the_lens_is_simapps_1_13_radians_at_160_by_120():
    # racecar.gazebo:67 (1.13 rad), :69-70 (640 x 480), resized to environments/constants.py:21
    # (160, 120) by sensors_rollout.py:174: the same angle across the smaller picture.
    config = default_config()
    assert math.radians(config["camera_fov"]) == pytest.approx(1.13)
    assert config["camera_size"] == (160, 120)
    assert CAR_FOV == 120.0


def test_the_mount_adds_up_simapps_joint_chain_from_the_rear_axle():
    # deepracer_single_cam.urdf: chassis 0.023249 above base_link (:41), zed_camera_joint
    # (0.091711, 0, 0.080023) pitched 0.2618 rad (:414-415), camera_joint (0.044755, 0, 0.04) in
    # that pitched frame (:517); the rear axle 0.081663 behind base_link and 0.01575 above the
    # chassis (:86), on wheels of 0.036 m: the lens 0.227 m ahead of the axle, 0.127 m up.
    forward, height, pitch = deepracer_mount()
    assert forward == pytest.approx(0.227, abs=5e-4)
    assert height == pytest.approx(0.127, abs=5e-4)
    assert pitch == pytest.approx(15.0, abs=1e-3)
    assert default_config()["camera_mount"] == (forward, height, pitch)


def test_the_stereo_pair_is_simapps_6_cm_apart():
    # deepracer_stereo_cam.urdf:398 (left camera at y +0.03) and :511 (right at -0.03).
    assert pytest.approx(0.06) == STEREO_BASELINE
    assert default_config()["stereo_baseline"] == STEREO_BASELINE


def test_the_lidar_sits_where_simapps_does_facing_backwards_above_bot_cars_shells():
    # deepracer_single_cam_lidar.urdf:536-537: hokuyo_joint 0.02913 m ahead of the chassis and
    # 0.16145 m above it, turned half round; the chassis 0.0817 m ahead of the rear axle and
    # 0.020 m above the ground. The shell (car_body_link_v3.STL) tops out 0.215 m up, so the
    # laser's rays meet another car's shell, as they meet a 0.3 m box.
    forward, height = lidar_mount()
    assert forward == pytest.approx(0.111, abs=5e-4)
    assert height == pytest.approx(0.182, abs=5e-4)
    config = default_config()
    assert config["lidar_mount"] == (forward, height) and config["lidar_heading"] == 180.0
    assert height < CarSpec().height == pytest.approx(0.215, abs=5e-4)


def view_of(texture: TrackTexture) -> PerspectiveView:
    forward, height, pitch = deepracer_mount()
    return PerspectiveView(texture, Lens(160, 120, SIMAPP_FOV), Mount(forward, height, pitch), SKY)


def ground_changing_at(ahead: float, *, pixels_per_metre: float, size: float) -> TrackTexture:
    """A ground ``size`` metres square around the origin, dark up to ``ahead`` metres in front of
    a lens at the origin looking along +x, light beyond."""
    pixels = int(size * pixels_per_metre)
    image = np.full((pixels, pixels), NEAR_GROUND, dtype=np.uint8)
    origin = np.array([-size / 2, -size / 2])
    image[:, int((ahead - origin[0]) * pixels_per_metre) :] = FAR_GROUND
    return TrackTexture(image=image, pixels_per_metre=pixels_per_metre, origin=origin)


@pytest.mark.parametrize(("ahead", "bottom_row"), [(0.14, FAR_GROUND), (0.16, NEAR_GROUND)])
def test_the_view_meets_the_ground_15_cm_ahead_of_the_lens(ahead, bottom_row):
    # The lowest row looks 15° + atan(59 / 126.3 px) down from 0.127 m: at the ground 0.151 m
    # ahead of the lens. Ground changing 0.14 m ahead is all the far side there; 0.16 m, the near.
    forward = deepracer_mount()[0]
    texture = ground_changing_at(forward + ahead, pixels_per_metre=500, size=2.0)
    frame = view_of(texture).render(0.0, 0.0, 0.0)
    assert (frame[-1] == bottom_row).all()


def test_the_horizon_sits_on_row_26_of_120():
    # f = 80 / tan(1.13 / 2) = 126.3 px; the horizon of a level ground is tan(15°) f = 33.8 rows
    # above the middle (60): row 26.2. Rows above it are sky; a few rows below, ground.
    view = view_of(ground_changing_at(-1000.0, pixels_per_metre=1.0, size=2000.0))
    assert 60 - view.lens.focal * math.tan(math.radians(15.0)) == pytest.approx(26.2, abs=0.05)
    frame = view.render(0.0, 0.0, 0.0)
    assert (frame[:27] == SKY).all()
    assert (frame[29:] == FAR_GROUND).all()


def sky_rows(env: DeepRacerEnv) -> int:
    """How many rows at the top of the car's first camera frame are all room: walls, or the
    background over them."""
    frame = env.reset(seed=0)[0]["FRONT_FACING_CAMERA"][0]
    room = env._cameras[0].room
    return int(np.isin(frame, (room.edge, room.background)).all(axis=1).sum())


@pytest.mark.parametrize(
    ("wall", "background_rows", "foot_row"), [(2.0, 0, 35), (6.0, 6, 30), (12.0, 17, 28)]
)
def test_over_the_walls_the_camera_sees_the_background(wall, background_rows, foot_row):
    # simapp's field walled 1 m high (reinvent_base_wall_field_only.dae): from 0.127 m up, the
    # top of a wall ``wall`` metres ahead is atan(0.873 / wall) above level, so 15° + that above
    # the lens's axis: row 60 - 126.3 tan(15° + atan(0.873 / wall)), -40.8 for 2 m (the wall
    # fills the view), 5.6 for 6 m, 16.1 for 12 m. Above it the background, below it the wall,
    # past the horizon (row 26.2) down to its foot, atan(0.127 / wall) below level: row
    # 60 - 126.3 tan(15° - atan(0.127 / wall)), 34.6 for 2 m, 29.2 for 6 m, 27.7 for 12 m.
    forward, height, pitch = deepracer_mount()
    texture = ground_changing_at(forward + 100.0, pixels_per_metre=20, size=2 * (forward + wall))
    lens = Lens(160, 120, SIMAPP_FOV)
    view = PerspectiveView(texture, lens, Mount(forward, height, pitch), SKY, Room(1.0, 178, SKY))
    frame = view.render(0.0, 0.0, 0.0)
    top = 60 - lens.focal * math.tan(math.radians(pitch) + math.atan((1.0 - height) / wall))
    column = frame[:, 80]
    assert (column == 178).sum() == background_rows == max(0, math.ceil(top))
    assert (column[background_rows:foot_row] == SKY).all()
    assert (column[foot_row:] == NEAR_GROUND).all()


def test_the_wide_lens_is_the_racers_choice_and_widens_the_picture():
    wide = DeepRacerEnv(track="rookie-loop", camera_lens="wide")
    assert wide.config["camera_fov"] == CAR_FOV
    # Wider, the picture shrinks toward its middle: the horizon, tan(15°) f above the middle,
    # comes down from row 26.2 (f = 126.3 px) to row 47.6 (f = 46.2 px). The sky covers the
    # rows down to the horizon and one more, and ground past the track's surroundings.
    simulated = sky_rows(DeepRacerEnv(track="rookie-loop"))
    assert 28 <= simulated < 49 <= sky_rows(wide)


def test_a_lens_that_is_not_offered_is_refused_in_words():
    with pytest.raises(ConfigError, match="The camera lens must be one of simulator, wide"):
        DeepRacerEnv(track="rookie-loop", camera_lens="fisheye")
