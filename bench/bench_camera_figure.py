"""The car's camera before and after issue 44, from the same pose: `python -m
bench.bench_camera_figure [--track reInvent2019_track] [--at 0.02] [--simapp-frame PNG]
[--out docs/camera-before-after.png]`.

Before: Pitlane's own camera (120° across, 0.12 m ahead of the rear axle, 0.12 m up, 25° down)
over its own track image (2 in borders centred on the edges, a 3 cm yellow centre line in
dashes of 15 cm, light surroundings and sky). After: simapp's camera and scene
(``simulator.camera``, ``simulator.texture``). Each is the 160 x 120 grayscale frame the policy
sees, drawn 3x. With ``--simapp-frame``, a frame of simapp's own camera (deepracer-utils'
tests/deepracer/model/sample-model/pictures/dr-demo-2.png, MIT; bench_deepracer_model fetches
them) is shown beside them, as the agent reads it (160 x 120, rl_coach's luma), though from
another track and pose.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from simulator.env import DeepRacerEnv
from simulator.room import Room
from simulator.texture import Style

# Pitlane's camera and track image before issue 44 (simulator/env.py and texture.py at d6827f9).
BEFORE_CAMERA = {
    "camera_fov": 120.0,
    "camera_mount": (0.12, 0.12, 25.0),
    "camera_texture_ppm": 64,
    "room": Room(height=None, background=150),  # no walls: a light sky from the horizon up
}
BEFORE_STYLE = Style(
    surroundings=(196, (200, 212, 216)),
    surface=(58, (62, 60, 58)),
    border=(250, (250, 250, 250)),
    centre_line=(214, (40, 200, 240)),
    start_line=(250, (250, 250, 250)),
    border_width=0.05,
    centre_line_width=0.03,
    dash=0.15,
    start_line_width=0.05,
    borders_inside=False,
)
SCALE = 3


def before(env: DeepRacerEnv) -> DeepRacerEnv:
    """``env`` seeing through the camera and track image Pitlane had before issue 44."""
    env.config.update(BEFORE_CAMERA, track_style=BEFORE_STYLE)
    env._build_sensors()  # the cameras again, from the changed config
    return env


def frame(env: DeepRacerEnv, at: float) -> np.ndarray:
    env.start = at
    observation, _ = env.reset(seed=0)
    return observation["FRONT_FACING_CAMERA"][0]


def simapp_frame(path: Path) -> np.ndarray:
    """A frame of simapp's camera as the agent reads it: 160 x 120, rl_coach's luma."""
    rgb = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    small = cv2.resize(rgb, (160, 120), interpolation=cv2.INTER_LINEAR).astype(np.float64)
    return np.round(small @ np.array([0.2989, 0.5870, 0.1140])).astype(np.uint8)


def labelled(image: np.ndarray, label: str) -> np.ndarray:
    big = cv2.resize(image, None, fx=SCALE, fy=SCALE, interpolation=cv2.INTER_NEAREST)
    big = cv2.cvtColor(big, cv2.COLOR_GRAY2BGR)
    cv2.rectangle(big, (0, 0), (big.shape[1], 22), (0, 0, 0), -1)
    cv2.putText(big, label, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return big


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--track", default="reInvent2019_track")
    parser.add_argument("--at", type=float, default=0.02, help="fraction of the lap")
    parser.add_argument("--simapp-frame", type=Path)
    parser.add_argument("--out", type=Path, default=Path("docs/camera-before-after.png"))
    args = parser.parse_args()
    old, new = before(DeepRacerEnv(track=args.track)), DeepRacerEnv(track=args.track)
    panels = [
        labelled(frame(old, args.at), "before: 120 deg, 25 deg down"),
        labelled(frame(new, args.at), "after: simapp's camera and scene"),
    ]
    if args.simapp_frame:
        panels.append(labelled(simapp_frame(args.simapp_frame), "simapp's own frame (elsewhere)"))
    gap = np.full((panels[0].shape[0], 8, 3), 255, dtype=np.uint8)
    figure = np.hstack([part for panel in panels for part in (panel, gap)][:-1])
    cv2.imwrite(str(args.out), figure, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    print(
        f"{args.out}: {figure.shape[1]} x {figure.shape[0]} px, {args.out.stat().st_size:,} bytes"
    )


if __name__ == "__main__":
    main()
