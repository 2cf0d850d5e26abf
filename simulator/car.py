"""The 1/18-scale car: its size, where its wheels are, and how it answers speed and steering.

The car follows a kinematic bicycle model about its rear axle, integrated in sub-steps within each
control step, with the lags a real car has: speed approaches the command with a first-order time
constant, and the steering servo turns at a limited rate. At DeepRacer's speeds (at most 4 m/s) a
1/18 car on carpet barely slips, so a tyre model would cost time without changing what a policy
learns; collisions with boxes and bot cars are detected by the PyBullet world (``simulator.world``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CarSpec:
    """DeepRacer's car at 1/18 scale. The origin is the middle of the rear axle."""

    length: float = 0.32  # [m] bumper to bumper
    width: float = 0.20  # [m]
    height: float = 0.12  # [m] of the body above the ground
    wheelbase: float = 0.165  # [m] rear axle to front axle
    wheel_track: float = 0.16  # [m] between the wheels' contact points, left to right
    rear_overhang: float = 0.075  # [m] rear axle to rear bumper
    # [m] ahead of the middle between the axles (DeepRacer's model origin): the point that
    # params["x"], ["y"] and the trace's X, Y report. simapp
    # bundle/markov/agent_ctrl/constants.py:24 (RELATIVE_POSITION_OF_FRONT_OF_CAR),
    # rollout_agent_ctrl.py:630-638 (01f5f01); the origin is base_link, midway between the
    # axles (bundle/urdf/deepracer/deepracer_single_cam.urdf:86,183).
    position_offset: float = 0.14
    max_steering: float = 30.0  # [deg]
    steering_rate: float = 360.0  # [deg/s] of the steering servo
    speed_time_constant: float = 0.25  # [s] to reach 63% of a new commanded speed
    min_speed: float = 0.1  # [m/s] commanded
    max_speed: float = 4.0  # [m/s] commanded

    @property
    def report_offset(self) -> float:
        """[m] from our origin (the rear axle) forward to the point DeepRacer reports."""
        return self.wheelbase / 2 + self.position_offset

    @property
    def centre_offset(self) -> float:
        """[m] from the origin forward to the middle of the body."""
        return self.length / 2 - self.rear_overhang


class Car:
    """The car's state (pose, speed, steering) and its motion over one control step."""

    def __init__(self, spec: CarSpec | None = None, substeps: int = 4) -> None:
        self.spec = spec or CarSpec()
        self.substeps = substeps
        self.x = self.y = self.yaw = 0.0  # [m], [m], [rad]
        self.speed = 0.0  # [m/s]
        self.steering = 0.0  # [rad]

    def place(self, x: float, y: float, yaw: float) -> None:
        """Put the car at rest at a pose."""
        self.x, self.y, self.yaw = x, y, yaw
        self.speed = self.steering = 0.0

    def step(self, speed_command: float, steering_command_deg: float, dt: float) -> float:
        """Drive for ``dt`` seconds toward the commands; the distance the origin moved [m]."""
        spec = self.spec
        h = dt / self.substeps
        blend = 1.0 - math.exp(-h / spec.speed_time_constant)
        target = math.radians(steering_command_deg)
        max_turn = math.radians(spec.steering_rate) * h
        start_x, start_y = self.x, self.y
        for _ in range(self.substeps):
            self.steering += min(max(target - self.steering, -max_turn), max_turn)
            self.speed += (speed_command - self.speed) * blend
            yaw_rate = self.speed * math.tan(self.steering) / spec.wheelbase
            # Exact integration along an arc (straight when the yaw rate is ~0).
            if abs(yaw_rate) > 1e-9:
                new_yaw = self.yaw + yaw_rate * h
                radius = self.speed / yaw_rate
                self.x += radius * (math.sin(new_yaw) - math.sin(self.yaw))
                self.y -= radius * (math.cos(new_yaw) - math.cos(self.yaw))
                self.yaw = new_yaw
            else:
                self.x += self.speed * h * math.cos(self.yaw)
                self.y += self.speed * h * math.sin(self.yaw)
        self.yaw = math.atan2(math.sin(self.yaw), math.cos(self.yaw))
        return math.hypot(self.x - start_x, self.y - start_y)

    def point_ahead(self, distance: float) -> tuple[float, float]:
        return self.x + distance * math.cos(self.yaw), self.y + distance * math.sin(self.yaw)

    @property
    def position(self) -> tuple[float, float]:
        """The point DeepRacer reports as the car's position: ``position_offset`` ahead of the
        middle between the axles."""
        return self.point_ahead(self.spec.report_offset)

    def wheels(self) -> np.ndarray:
        """The wheels' contact points, (4, 2): rear left, rear right, front left, front right."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        half = self.spec.wheel_track / 2
        local = np.array(
            [[0.0, half], [0.0, -half], [self.spec.wheelbase, half], [self.spec.wheelbase, -half]]
        )
        return np.column_stack(
            [self.x + local[:, 0] * c - local[:, 1] * s, self.y + local[:, 0] * s + local[:, 1] * c]
        )
