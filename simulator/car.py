"""The 1/18-scale car: DeepRacer's simulated car as a rigid body on four tyres that grip until
friction runs out.

DeepRacer trains in Gazebo (ODE): a 6.6 kg rigid chassis on four wheel bodies, each wheel driven by
a velocity controller toward ``speed / 0.035`` rad/s and the front pair turned by position
controllers, the tyres held by Coulomb friction (mu 0.5). We model the same car as a single-track
(bicycle) rigid body in the plane: each axle's contact carries the two wheels' forces, the tyres
do not slip while the force they need stays within ``mu * N`` along and across the wheel (ODE's
friction pyramid), and slide with that force once it does not. Within the grip limit the car
follows the kinematic bicycle's arc exactly; beyond it the front slides (understeer) or the rear
steps out (oversteer, a spin). The wheel controllers push the car toward the wheel speed they are
asked for, as hard as the friction allows, and the steering hinges turn as their controller
drives them, so how fast the car speeds up, brakes and turns comes from the controllers' gains,
the parts' inertia and the grip, not from a lag constant.

Each sub-step solves the contact forces as ODE's solver does: velocity constraints at the two
axles (no sliding across a wheel; along it, the wheel controller's pull toward its target),
solved by projected Gauss-Seidel with each force clipped to the friction it can have. The
solve is implicit, so it stays stable at any step; collisions with boxes and bot cars are
detected by the PyBullet world (``simulator.world``).

Every number below names its source: deepracer-simapp at 2fc2d75c, the last commit of the ROS 1 /
Gazebo classic simulator that the DeepRacer console ran. Its car is the "kinematics" car of
physics version 5, the version every model's metadata carries (ours too) and every virtual event
forces (bundle/markov/agent_ctrl/rollout_agent_ctrl.py:103-106): for it racecar.launch:55 and
bundle/markov/spawn/models/agent_model.py:51-55,74 load
bundle/src/deepracer_simulation_environment/config/racecar_control_kinematics.yaml, whose
controllers pass the commands through to gazebo_ros_control's own PID loops (its
``gazebo_ros_control/pid_gains``), run at every 1 ms physics step. Older versions' car
(racecar_control.yaml's effort controllers) differs in one thing that matters: its steering PD
damps the hinge's velocity, a smooth 0.5 s lag, where version 5's differentiates the error, which
kicks the hinge toward every new command (``simulator.steering``). Its ROS 2 port (01f5f01)
keeps the URDF's numbers but imposes the wheels' speed directly and steers with a 0.17 s lag
(gz_ros2_control's position emulation); we follow the simulator every console model trained in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from simulator.steering import Hinge

GRAVITY = 9.81  # [m/s²]
URDF = "bundle/urdf/deepracer/deepracer_single_cam.urdf"  # at 2fc2d75c
WHEEL_MASS = 0.34055  # [kg] each wheel: URDF:46 (and each wheel link)
WHEEL_IZZ = 0.00026046  # [kg m²] a wheel about the vertical axis: URDF:54
HINGE_MASS = 0.1  # [kg] each steering hinge: URDF:152
HINGE_IZZ = 4e-6  # [kg m²]: URDF:160
REAR_AXLE_X = -0.081663  # [m] rear wheel joints, in the chassis frame: URDF:80-81 (left), 133
FRONT_AXLE_X = 0.082311  # [m] front steering hinges: URDF:177-178 (left), 276
REAR_WHEEL_Y = 0.08105  # [m] half the rear track: URDF:81
FRONT_WHEEL_Y = 0.079601  # [m] half the front track: URDF:178
CHASSIS_Z = 0.023249  # [m] chassis above base_link: URDF:35-36 (base_link_joint)
REAR_AXLE_Z, FRONT_AXLE_Z = 0.01575, 0.011759  # [m] wheel centres above the chassis: URDF:81, 178


# The lidar (deepracer_single_cam_lidar.urdf:532-541, 01f5f01): hokuyo_joint puts the laser link
# 0.02913 m ahead of the chassis origin and 0.16145 m above it, turned half round (rpy 0 0
# 3.1416): its scan faces backwards.
LIDAR_JOINT = (0.02913, 0.16145)  # [m] forward, up in the chassis frame


def lidar_mount(wheel_radius: float = 0.036) -> tuple[float, float]:
    """simapp's lidar as (forward of our car's origin, the middle of the rear axle [m]; height
    above the ground [m]): 0.111 m, 0.182 m."""
    ground = REAR_AXLE_Z + CHASSIS_Z - wheel_radius  # the tread, above base_link
    return LIDAR_JOINT[0] - REAR_AXLE_X, LIDAR_JOINT[1] + CHASSIS_Z - ground


@dataclass(frozen=True)
class Part:
    """A rigid part of the car: its mass, where its centre is (chassis frame, x forward, z up,
    from the chassis origin) and its moment of inertia about its own vertical axis."""

    mass: float  # [kg]
    x: float  # [m]
    y: float  # [m]
    z: float  # [m]
    izz: float  # [kg m²]


def deepracer_parts() -> tuple[Part, ...]:
    """The single-camera car's links (URDF at 2fc2d75c); the camera and lidar links weigh 1 g or
    less and are left out. The stereo car's differ by 2 g (its second camera link)."""
    wheels = [
        Part(WHEEL_MASS, axle, side * half, z, WHEEL_IZZ)
        for axle, half, z in (
            (REAR_AXLE_X, REAR_WHEEL_Y, REAR_AXLE_Z),
            (FRONT_AXLE_X, FRONT_WHEEL_Y, FRONT_AXLE_Z),
        )
        for side in (1, -1)
    ]
    hinges = [
        Part(HINGE_MASS, FRONT_AXLE_X, side * FRONT_WHEEL_Y, FRONT_AXLE_Z, HINGE_IZZ)
        for side in (1, -1)
    ]
    # The chassis: 5.0 kg, its centre at the chassis origin, izz 0.05865 kg m²: URDF:10-24.
    return (Part(5.0, 0.0, 0.0, 0.0, 0.05865), *wheels, *hinges)


@dataclass(frozen=True)
class CarSpec:
    """DeepRacer's simulated car at 1/18 scale. The car's origin here is the middle of the rear
    axle; DeepRacer's (base_link) is 0.0817 m ahead of it, nearly midway between the axles."""

    # The body, for collisions, the lidar and drawing.
    length: float = 0.32  # [m] bumper to bumper
    width: float = 0.20  # [m]
    # [m] of the body above the ground: its shell's top, 0.195 m above car_body_link
    # (bundle/meshes/deepracer/car_body_link_v3.STL, its highest vertex), which sits 2e-5 m
    # above the chassis (deepracer_single_cam_lidar.urdf:583-586, 01f5f01), itself 0.020 m up
    height: float = 0.215
    rear_overhang: float = 0.075  # [m] rear axle to rear bumper
    wheel_track: float = 2 * REAR_WHEEL_Y  # [m] between the rear wheels' contact points
    # [m] ahead of base_link: the point that params["x"], ["y"] and the trace's X, Y report. simapp
    # bundle/markov/agent_ctrl/constants.py:24 (RELATIVE_POSITION_OF_FRONT_OF_CAR),
    # rollout_agent_ctrl.py:630-638 (01f5f01).
    position_offset: float = 0.14
    parts: tuple[Part, ...] = field(default_factory=deepracer_parts)

    # The action's limits: simapp bundle/markov/agent_ctrl/constants.py:40-44 (2fc2d75c).
    max_steering: float = 30.0  # [deg]
    min_speed: float = 0.1  # [m/s] commanded
    max_speed: float = 4.0  # [m/s] commanded

    # Tyres: mu1 = mu2 = 0.5 on every wheel, racecar.gazebo:11-45; the track sets no friction of
    # its own, and ODE takes the smaller of the two. Gazebo's ODE clips the force along and across
    # each contact separately (its default "pyramid" friction model), as we do per axle.
    friction: float = 0.5
    # [m] the wheels' collision meshes (bundle/meshes/deepracer/*_wheel.STL): 36.0 mm to the tread.
    wheel_radius: float = 0.036
    # [m] the radius the action's speed is divided by to get the wheels' angular velocity,
    # agent_ctrl/utils.py:212-217 and rollout_agent_ctrl.py:687. A wheel turning at speed/0.035
    # rad/s on a 0.036 m tread rolls 2.9% faster than the action asks.
    command_radius: float = 0.035
    # [rad/s] the wheel joints' velocity limit, URDF:89-91; ros_control's saturation handle stops
    # driving a wheel past it, so the car rolls at most 100 * 0.036 = 3.6 m/s.
    wheel_speed_limit: float = 100.0
    # [N m per rad/s] the wheels' velocity loops, gazebo_ros_control's VELOCITY_PID (the
    # transmissions are VelocityJointInterface, urdf/deepracer_kinematics/macros.xacro), the same
    # on both wheels of an axle: racecar_control_kinematics.yaml:37-38 (rear), 39-40 (front); the
    # torque is capped at 10 N m (URDF:89-91), 280 N at the tread, far beyond the grip, so the cap
    # never binds.
    rear_wheel_gain: float = 1.0
    front_wheel_gain: float = 0.5
    # The steering hinges (PositionJointInterface, the same macros.xacro): ros_control's
    # PositionJointSaturationHandle moves the command at most at the joint's velocity limit
    # (gazebo_ros_control default_robot_hw_sim.cpp, registerJointLimits), then gazebo_ros_control's
    # POSITION_PID loop (racecar_control_kinematics.yaml:41-42) turns the hinge with a torque of
    # p * error + d * d(error)/dt, the derivative taken between control periods (control_toolbox
    # Pid::computeCommand(error, dt)), clipped to the joint's effort limit. Limits: URDF:186-190.
    steering_p: float = 1.0  # [N m/rad]
    steering_d: float = 0.5  # [N m s/rad]
    steering_effort: float = 10.0  # [N m]
    steering_rate_limit: float = 100.0  # [rad/s]
    # [kg m²] what the hinge turns: its own link and the wheel about the vertical axis through the
    # wheel's centre, where the wheel's joint sits (URDF:160, 206, 230-233).
    steering_inertia: float = HINGE_IZZ + WHEEL_IZZ
    # [s] Gazebo's physics step (its default max_step_size: no world in bundle/worlds sets one);
    # gazebo_ros_control, given no controlPeriod (racecar.gazebo:47-53), updates at every step.
    control_period: float = 0.001

    @cached_property
    def mass(self) -> float:
        return sum(part.mass for part in self.parts)

    @cached_property
    def _centre(self) -> tuple[float, float]:
        """The centre of mass: ahead of the chassis origin [m], above the ground [m]."""
        x = sum(p.mass * p.x for p in self.parts) / self.mass
        z = sum(p.mass * p.z for p in self.parts) / self.mass
        # The ground is the wheels' tread: the rear axle's height less the wheel radius.
        ground = REAR_AXLE_Z + CHASSIS_Z - self.wheel_radius
        return x, z + CHASSIS_Z - ground

    @property
    def wheelbase(self) -> float:
        return FRONT_AXLE_X - REAR_AXLE_X

    @property
    def rear_to_centre(self) -> float:
        """[m] from the rear axle forward to the centre of mass."""
        return self._centre[0] - REAR_AXLE_X

    @property
    def centre_height(self) -> float:
        """[m] of the centre of mass above the ground: it moves weight between the axles."""
        return self._centre[1]

    @cached_property
    def yaw_inertia(self) -> float:
        """[kg m²] about the vertical axis through the centre of mass."""
        cx = self._centre[0]
        return sum(p.izz + p.mass * ((p.x - cx) ** 2 + p.y**2) for p in self.parts)

    @property
    def top_speed(self) -> float:
        """[m/s] the fastest the wheels are driven: the action's top speed or the joint limit."""
        return self.wheel_target(self.max_speed)

    def wheel_target(self, speed: float) -> float:
        """[m/s] the speed of the tread the wheel controllers drive toward for a commanded speed."""
        return min(speed / self.command_radius, self.wheel_speed_limit) * self.wheel_radius

    @property
    def steering_time_constant(self) -> float:
        """[s] how a steering error left once the hinge has stopped closes: a first-order lag of
        d / p (the damping, d * d(error)/dt, then balances the pull, p * error)."""
        return self.steering_d / self.steering_p

    @property
    def base_link(self) -> float:
        """[m] from our origin forward to DeepRacer's model origin, base_link (the chassis origin,
        URDF:35-36): 0.3 mm short of midway between the axles."""
        return -REAR_AXLE_X

    @property
    def report_offset(self) -> float:
        """[m] from our origin (the rear axle) forward to the point DeepRacer reports."""
        return self.base_link + self.position_offset

    @property
    def centre_offset(self) -> float:
        """[m] from the origin forward to the middle of the body."""
        return self.length / 2 - self.rear_overhang


SOLVER_ITERATIONS = 4  # Gauss-Seidel sweeps over the four axle constraints per sub-step


def _clip(value: float, limit: float) -> float:
    """``value`` within ±``limit``."""
    return limit if value > limit else -limit if value < -limit else value


class Car:
    """The car's state (pose, velocity, steering) and its motion over one control step.

    ``x``, ``y`` (the middle of the rear axle) and ``yaw`` are its pose; ``speed`` its velocity
    along its heading, ``lateral_speed`` across it (leftward, at the centre of mass), ``yaw_rate``
    its turning, ``steering`` the front wheels' angle [rad]."""

    def __init__(self, spec: CarSpec | None = None, substeps: int = 8) -> None:
        self.spec = spec or CarSpec()
        self.substeps = substeps
        self.place(0.0, 0.0, 0.0)

    def place(self, x: float, y: float, yaw: float) -> None:
        """Put the car at rest at a pose."""
        self.x, self.y, self.yaw = x, y, yaw
        self.speed = self.lateral_speed = self.yaw_rate = 0.0
        self.hinge = Hinge(self.spec)
        self._impulses = [0.0, 0.0, 0.0, 0.0]  # the last sub-step's, to start the next solve
        self._accel = 0.0  # [m/s²] along the heading in the last sub-step: it moves the weight
        # Whether an axle slid sideways through most of the last control step: a slide lasts,
        # where a new steering command saturates the front tyres for a sub-step as it kicks.
        self.sliding = False

    @property
    def steering(self) -> float:
        """[rad] the front wheels' angle, left positive."""
        return self.hinge.angle

    def periods(self, dt: float) -> int:
        """The hinge's control periods in ``dt`` seconds (1/15 s: 67 of 1 ms)."""
        return max(1, round(dt / self.spec.control_period))

    def _periods(self, dt: float) -> list[int]:
        """The hinge's control periods in each of a step's sub-steps: ``dt`` rounded to whole
        periods (1/15 s: 67 of 1 ms), shared out as evenly as they go."""
        total = self.periods(dt)
        n = self.substeps
        return [(i + 1) * total // n - i * total // n for i in range(n)]

    @property
    def slip_angle(self) -> float:
        """[rad] between the heading and the direction the centre of mass travels."""
        return math.atan2(self.lateral_speed, self.speed)

    # Long because: it is the simulator's innermost loop (sub-steps of solver sweeps), written in
    # scalar locals: a call per constraint would cost a third of the steps/s (bench_simulator).
    def step(self, speed_command: float, steering_command_deg: float, dt: float) -> float:
        """Drive for ``dt`` seconds toward the commands; the distance the origin moved [m]."""
        spec = self.spec
        h = dt / self.substeps
        m, inertia = spec.mass, spec.yaw_inertia
        b = spec.rear_to_centre
        a = spec.wheelbase - b
        length, height, mu = spec.wheelbase, spec.centre_height, spec.friction
        target = spec.wheel_target(speed_command)
        steer_target = math.radians(steering_command_deg)
        hinge = self.hinge
        # The wheel controllers, as dampers at the tread toward the target speed: a torque of
        # gain * (target - speed) / radius per wheel, two wheels an axle. In the solve this is a
        # soft constraint whose softness is 1 / (h * stiffness) [Catto, "Soft Constraints"].
        radius = spec.wheel_radius
        soft_rear = 1.0 / (h * 2 * spec.rear_wheel_gain / radius**2)
        soft_front = 1.0 / (h * 2 * spec.front_wheel_gain / radius**2)
        inv_m, inv_i = 1.0 / m, 1.0 / inertia
        k_rear_long = inv_m + soft_rear
        k_rear_lat = inv_m + b * b * inv_i
        weight_rear, weight_front = m * GRAVITY * a / length, m * GRAVITY * b / length
        # The solve runs in the car's frame: u along the heading, v to the left, at the centre
        # of mass; r the yaw rate. The frame turns with the car, by r * h each sub-step.
        yaw = self.yaw
        cos_y, sin_y = math.cos(yaw), math.sin(yaw)
        u, v = self.speed, self.lateral_speed
        r = self.yaw_rate
        cx, cy = self.x + b * cos_y, self.y + b * sin_y  # the centre of mass
        start_x, start_y = self.x, self.y
        p_rl, p_rt, p_fl, p_ft = self._impulses  # rear/front, along/across the wheel [N s]
        saturated = 0  # sub-steps in which an axle's tyres slid sideways
        for periods in self._periods(dt):
            delta = hinge.turn(steer_target, periods)
            sin_d, cos_d = math.sin(delta), math.cos(delta)
            # Each axle's load: its static share, moved forward under braking and back under
            # acceleration by the centre of mass's height.
            transfer = m * self._accel * height / length
            limit_rear = mu * (weight_rear + transfer) * h
            limit_front = mu * (weight_front - transfer) * h
            limit_rear = limit_rear if limit_rear > 0.0 else 0.0
            limit_front = limit_front if limit_front > 0.0 else 0.0
            # How each front impulse moves u, v and r.
            cu, su = cos_d * inv_m, sin_d * inv_m
            ar_long, ar_lat = a * sin_d * inv_i, a * cos_d * inv_i
            k_front_long = inv_m + a * sin_d * ar_long + soft_front
            k_front_lat = inv_m + a * cos_d * ar_lat
            # Start from the last sub-step's impulses (a warm start: the solve then converges
            # in a few sweeps), each within this sub-step's friction.
            p_rl = _clip(p_rl, limit_rear)
            p_rt = _clip(p_rt, limit_rear)
            p_fl = _clip(p_fl, limit_front)
            p_ft = _clip(p_ft, limit_front)
            u += p_rl * inv_m + p_fl * cu - p_ft * su
            v += p_rt * inv_m + p_fl * su + p_ft * cu
            r += -b * p_rt * inv_i + p_fl * ar_long + p_ft * ar_lat
            for _ in range(SOLVER_ITERATIONS):
                # Rear, along the wheels: the controllers' pull toward the target speed.
                new = _clip(p_rl + (target - u - soft_rear * p_rl) / k_rear_long, limit_rear)
                u += (new - p_rl) * inv_m
                p_rl = new
                # Rear, across the wheels: no sliding.
                new = _clip(p_rt - (v - r * b) / k_rear_lat, limit_rear)
                change, p_rt = new - p_rt, new
                v += change * inv_m
                r -= change * b * inv_i
                # Front, along the wheels.
                along = u * cos_d + (v + r * a) * sin_d
                new = _clip(p_fl + (target - along - soft_front * p_fl) / k_front_long, limit_front)
                change, p_fl = new - p_fl, new
                u += change * cu
                v += change * su
                r += change * ar_long
                # Front, across the wheels.
                across = -u * sin_d + (v + r * a) * cos_d
                new = _clip(p_ft - across / k_front_lat, limit_front)
                change, p_ft = new - p_ft, new
                u -= change * su
                v += change * cu
                r += change * ar_lat
            saturated += abs(p_rt) >= limit_rear or abs(p_ft) >= limit_front
            self._accel = (p_rl + p_fl * cos_d - p_ft * sin_d) / (m * h)
            # Move, then turn the frame with the car.
            cx += (u * cos_y - v * sin_y) * h
            cy += (u * sin_y + v * cos_y) * h
            turn = r * h
            yaw += turn
            cos_t, sin_t = math.cos(turn), math.sin(turn)
            u, v = u * cos_t + v * sin_t, v * cos_t - u * sin_t
            cos_y, sin_y = math.cos(yaw), math.sin(yaw)
        yaw = math.atan2(sin_y, cos_y)
        self.yaw, self.yaw_rate = yaw, r
        self.x, self.y = cx - b * cos_y, cy - b * sin_y
        self._impulses = [p_rl, p_rt, p_fl, p_ft]
        self.speed, self.lateral_speed = u, v
        self.sliding = 2 * saturated > self.substeps
        return math.hypot(self.x - start_x, self.y - start_y)

    def point_ahead(self, distance: float) -> tuple[float, float]:
        return self.x + distance * math.cos(self.yaw), self.y + distance * math.sin(self.yaw)

    @property
    def position(self) -> tuple[float, float]:
        """The point DeepRacer reports as the car's position: ``position_offset`` ahead of
        base_link."""
        return self.point_ahead(self.spec.report_offset)

    def wheels(self) -> np.ndarray:
        """The wheels' contact points, (4, 2): rear left, rear right, front left, front right."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        half = self.spec.wheel_track / 2
        base = self.spec.wheelbase
        local = np.array([[0.0, half], [0.0, -half], [base, half], [base, -half]])
        return np.column_stack(
            [self.x + local[:, 0] * c - local[:, 1] * s, self.y + local[:, 0] * s + local[:, 1] * c]
        )
